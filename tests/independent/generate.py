#!/usr/bin/env python3
"""Independent synthetic-image generator for ffdic (ground truth for the diagnosis tests).

Written from physics and from the test brief only: it shares no code and no file with ffdic's
src/.  See README.md beside this file for the physics, the conventions and the spec format.

    python generate.py SPEC.json OUT_DIR [--overwrite] [--quiet]

or, from Python, ``generate(spec: dict, out_dir) -> truth dict``.
"""

from __future__ import annotations

import os

# Keep BLAS single-threaded (the machine is shared); only effective if numpy is not yet imported.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse
import copy
import json
import math
import re
import shutil
import sys
import time
import zlib
from pathlib import Path

import numpy as np
import tifffile

GENERATOR_NAME = "ffdic tests/independent/generate.py"
TRUTH_FORMAT = "ffdic-independent-truth/1"
FWHM_PER_SIGMA = 2.0 * math.sqrt(2.0 * math.log(2.0))  # 2.3548200450309493

# --------------------------------------------------------------------------------------------
# Spec: defaults, merging, validation
# --------------------------------------------------------------------------------------------

DEFAULT_SPEC = {
    "name": "indep",
    "seed": 1,
    "width": 640,
    "height": 540,
    "scale_px_per_mm": 13.0,
    "bit_depth": 16,
    "white_level_dn": 30000.0,
    "gain_e_per_dn": 0.5,
    "read_noise_dn": 20.0,
    "dark_offset_dn": 0.0,
    "noise": True,
    "patterns": [
        {"label": "a", "profile": "gaussian", "dot_diameter_mm": 0.3, "dot_spacing_mm": 0.45,
         "contrast": 0.7}
    ],
    "state_print": "nominal",
    "moves": [
        {"id": "x5mm", "dx_mm": 5.0, "dy_mm": 0.0},
        {"id": "y5mm", "dx_mm": 0.0, "dy_mm": 5.0},
    ],
    "step_series": [],
    "repeats": 1,
    "stage": {
        "travel_scale": 1.0,
        "misalign_rad": 0.0,
        "constant_offset_px": [0.0, 0.0],
        "repeatability_um": 0.0,
        "per_run_offsets_px": {},
    },
    "stated_repeatability_um": None,
    "effects": {
        "rotation_rad": 0.0,
        "scale_ds": 0.0,
        "k1_per_px2": 0.0,
        "psf_sigma_px": 0.0,
        "vignetting_v": 0.0,
        "fill_factor": [1.0, 1.0],
        "illumination_gain": 1.0,
    },
    "render": {
        "window_sigmas": 6.0,
        "disk_supersample": 8,
        "write_dot_lists": True,
        "overlap_samples": 20000,
    },
    "overwrite": False,
    # The camera's own binning/decimation: extra frames of every position read out in each mode.
    "hardware_readouts": [],
}

PATTERN_DEFAULTS = {
    "profile": "gaussian",
    "dot_diameter_mm": 0.3,
    "dot_spacing_mm": 0.45,
    "contrast": 0.7,
    "diameter_cv": 0.0,
    "edge_softness_mm": 0.0,
}

# Keys added after the first release. They are NOT written into the effective spec unless the
# user gives them, so a spec without them produces byte-identical files (dataset.json included,
# whose generator.spec is the effective spec). Read them with opt_top / opt_effect.
OPTIONAL_TOP = {
    "working_distance_mm": 300.0,     # Z: pupil → where the optical axis meets the target plane
    "state_working_distance": False,  # true: dataset.json gets "working_distance_mm"
}
OPTIONAL_EFFECTS = {
    "tilt_about_y_rad": 0.0,          # θy: +x side of the target farther from the camera for θy > 0
    "tilt_about_x_rad": 0.0,          # θx: +y side of the target farther from the camera for θx > 0
    "k2_norm": 0.0,                   # Brown–Conrady, normalised by r0 (half diagonal)
    "p1_norm": 0.0,
    "p2_norm": 0.0,
    "distortion_centre_px": [0.0, 0.0],  # distortion centre relative to the optical axis (px)
    "target_bow_per_mm": 0.0,         # κ: depth offset κ|P|²/2 (mm) of a bowed target
    "target_saddle_per_mm": 0.0,      # κs: depth offset κs (Px² − Py²)/2 (mm) of a saddle-shaped target
    "lamp_ramp_per_px": [0.0, 0.0],   # moved frames lit by a drifted lamp: × (1 + ax·x + ay·y)
}


def opt_top(spec: dict, key: str):
    v = spec.get(key)
    return OPTIONAL_TOP[key] if v is None else v


def opt_effect(spec: dict, key: str):
    v = spec["effects"].get(key)
    return OPTIONAL_EFFECTS[key] if v is None else v


_ID_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.+-]*$")
_PER_MOVE_OVERRIDES = ("rotation_rad", "scale_ds", "illumination_gain")


class SpecError(ValueError):
    pass


def _deep_merge(base: dict, over: dict) -> dict:
    out = copy.deepcopy(base)
    for k, v in over.items():
        if isinstance(v, dict) and isinstance(out.get(k), dict) and k != "per_run_offsets_px":
            out[k] = _deep_merge(out[k], v)
        else:
            out[k] = copy.deepcopy(v)
    return out


def effective_spec(user_spec: dict) -> dict:
    """The spec with every default filled in, checked. Unknown keys are kept."""
    if not isinstance(user_spec, dict):
        raise SpecError("spec must be a JSON object")
    spec = _deep_merge(DEFAULT_SPEC, user_spec)
    if "patterns" in user_spec:
        spec["patterns"] = copy.deepcopy(user_spec["patterns"])
    if "moves" in user_spec:
        spec["moves"] = copy.deepcopy(user_spec["moves"])
    pats = []
    for p in spec["patterns"]:
        if not isinstance(p, dict) or "label" not in p:
            raise SpecError("every pattern needs a label")
        q = dict(PATTERN_DEFAULTS)
        q.update(p)
        if "placement" not in q:
            q["placement"] = "poisson" if q["profile"] == "gaussian" else "dart"
        if q["profile"] == "disk" and "min_gap_mm" not in q:
            q["min_gap_mm"] = 0.05 * float(q["dot_diameter_mm"])
        pats.append(q)
    spec["patterns"] = pats
    eff = spec["effects"]
    if "k1_norm" in eff and eff["k1_norm"] is not None:
        r0sq = 0.25 * (spec["width"] ** 2 + spec["height"] ** 2)
        k1 = float(eff["k1_norm"]) / r0sq
        if "k1_per_px2" in user_spec.get("effects", {}) and user_spec["effects"]["k1_per_px2"] not in (None, 0, 0.0):
            if not math.isclose(k1, float(user_spec["effects"]["k1_per_px2"]), rel_tol=1e-9):
                raise SpecError("effects.k1_norm and effects.k1_per_px2 disagree")
        eff["k1_per_px2"] = k1
    _validate(spec)
    return spec


def _validate(spec: dict) -> None:
    def pos_int(k):
        v = spec[k]
        if not isinstance(v, int) or isinstance(v, bool) or v <= 0:
            raise SpecError(f"{k} must be a positive integer")

    pos_int("width")
    pos_int("height")
    if not isinstance(spec["seed"], int) or spec["seed"] < 0:
        raise SpecError("seed must be a non-negative integer")
    if not (float(spec["scale_px_per_mm"]) > 0):
        raise SpecError("scale_px_per_mm must be positive")
    if spec["bit_depth"] not in (8, 16):
        raise SpecError("bit_depth must be 8 or 16")
    full = 2 ** spec["bit_depth"] - 1
    if not (0 < float(spec["white_level_dn"]) <= full):
        raise SpecError(f"white_level_dn must lie in (0, {full}]")
    g = spec["gain_e_per_dn"]
    if g is not None and not (float(g) > 0):
        raise SpecError("gain_e_per_dn must be positive (or null: no shot noise)")
    if float(spec["read_noise_dn"]) < 0:
        raise SpecError("read_noise_dn must be >= 0")
    if spec["state_print"] not in ("none", "nominal", "characterised"):
        raise SpecError("state_print must be none, nominal or characterised")
    if not isinstance(spec["repeats"], int) or spec["repeats"] < 0:
        raise SpecError("repeats must be an integer >= 0")
    if not spec["patterns"]:
        raise SpecError("patterns is empty")
    labels = set()
    for p in spec["patterns"]:
        lab = p["label"]
        if not isinstance(lab, str) or not _ID_RE.match(lab):
            raise SpecError(f"pattern label {lab!r} must match {_ID_RE.pattern}")
        if lab in labels:
            raise SpecError(f"duplicate pattern label {lab!r}")
        labels.add(lab)
        if p["profile"] not in ("gaussian", "disk"):
            raise SpecError(f"pattern {lab}: profile must be gaussian or disk")
        if not (0 < float(p["contrast"]) <= 1):
            raise SpecError(f"pattern {lab}: contrast must lie in (0, 1]")
        if not (float(p["dot_diameter_mm"]) > 0 and float(p["dot_spacing_mm"]) > 0):
            raise SpecError(f"pattern {lab}: dot_diameter_mm and dot_spacing_mm must be positive")
        if not (0 <= float(p["diameter_cv"]) < 0.3):
            raise SpecError(f"pattern {lab}: diameter_cv must lie in [0, 0.3)")
        if float(p["edge_softness_mm"]) < 0:
            raise SpecError(f"pattern {lab}: edge_softness_mm must be >= 0")
        allowed = ("poisson",) if p["profile"] == "gaussian" else ("dart", "jittered_grid")
        if p["placement"] not in allowed:
            raise SpecError(f"pattern {lab}: placement must be one of {allowed}")
    ids = set()
    for m in spec["moves"]:
        if not _ID_RE.match(str(m.get("id", ""))):
            raise SpecError(f"move id {m.get('id')!r} must match {_ID_RE.pattern}")
        if m["id"] in ids:
            raise SpecError(f"duplicate move id {m['id']!r}")
        ids.add(m["id"])
        float(m["dx_mm"]), float(m["dy_mm"])
    for s in spec["step_series"]:
        if not _ID_RE.match(str(s.get("id", ""))):
            raise SpecError(f"step series id {s.get('id')!r} must match {_ID_RE.pattern}")
        if not isinstance(s.get("count"), int) or s["count"] < 1:
            raise SpecError(f"step series {s['id']}: count must be a positive integer")
        float(s["dx_step_mm"]), float(s["dy_step_mm"])
    eff = spec["effects"]
    ff = eff["fill_factor"]
    if len(ff) != 2 or not all(0 < float(f) <= 1 for f in ff):
        raise SpecError("effects.fill_factor must be [fx, fy] with each in (0, 1]")
    if float(eff["psf_sigma_px"]) < 0:
        raise SpecError("effects.psf_sigma_px must be >= 0")
    if not (0 <= float(eff["vignetting_v"]) < 1):
        raise SpecError("effects.vignetting_v must lie in [0, 1)")
    if float(eff["scale_ds"]) <= -0.5:
        raise SpecError("effects.scale_ds too negative")
    Z = opt_top(spec, "working_distance_mm")
    if isinstance(Z, bool) or not isinstance(Z, (int, float)) or not (math.isfinite(Z) and Z > 0):
        raise SpecError("working_distance_mm must be a positive number (mm)")
    if not isinstance(opt_top(spec, "state_working_distance"), bool):
        raise SpecError("state_working_distance must be true or false")
    for k in ("tilt_about_y_rad", "tilt_about_x_rad", "k2_norm", "p1_norm", "p2_norm", "target_bow_per_mm",
              "target_saddle_per_mm"):
        v = opt_effect(spec, k)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise SpecError(f"effects.{k} must be a finite number")
    for k in ("tilt_about_y_rad", "tilt_about_x_rad"):
        if abs(float(opt_effect(spec, k))) >= math.radians(60):
            raise SpecError(f"effects.{k} must lie within ±60° (radians)")
    c = opt_effect(spec, "distortion_centre_px")
    if (not isinstance(c, (list, tuple)) or len(c) != 2
            or not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in c)):
        raise SpecError("effects.distortion_centre_px must be [dx, dy] (px, relative to the optical axis)")
    ramp = opt_effect(spec, "lamp_ramp_per_px")
    if (not isinstance(ramp, (list, tuple)) or len(ramp) != 2
            or not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in ramp)):
        raise SpecError("effects.lamp_ramp_per_px must be [ax, ay] (1/px)")
    if abs(ramp[0]) * int(spec["width"]) / 2 + abs(ramp[1]) * int(spec["height"]) / 2 >= 0.5:
        raise SpecError("effects.lamp_ramp_per_px changes the irradiance by half or more inside the frame")
    st = spec["stage"]
    if len(st["constant_offset_px"]) != 2:
        raise SpecError("stage.constant_offset_px must be [dx, dy]")
    if float(st["repeatability_um"]) < 0:
        raise SpecError("stage.repeatability_um must be >= 0")
    names = set()
    for ro in spec["hardware_readouts"]:
        name = ro.get("name")
        if not isinstance(name, str) or not name or name in names:
            raise SpecError("every hardware read-out needs a unique name")
        names.add(name)
        b, d = ro.get("binning", [1, 1]), ro.get("decimation", [1, 1])
        if len(b) != 2 or len(d) != 2 or not all(isinstance(f, int) and 1 <= f <= 8 for f in b + d):
            raise SpecError(f"read-out {name}: binning and decimation are [x, y] integers 1..8")
        if any(b[i] > 1 and d[i] > 1 for i in range(2)) or b + d == [1, 1, 1, 1]:
            raise SpecError(f"read-out {name}: per axis binning or decimation, and at least one of them")
        if ro.get("value", "average") not in ("average", "sum"):
            raise SpecError(f"read-out {name}: value must be average or sum")
        if ro.get("domain", "digital") not in ("digital", "charge"):
            raise SpecError(f"read-out {name}: domain must be digital or charge")
    if not (int(spec["render"]["disk_supersample"]) >= 8):
        raise SpecError("render.disk_supersample must be >= 8 (strips of at most 1/8 px)")
    if not (float(spec["render"]["window_sigmas"]) >= 4):
        raise SpecError("render.window_sigmas must be >= 4")


# --------------------------------------------------------------------------------------------
# Special functions: tabulated Φ (standard normal CDF) and Ψ1(t) = tΦ(t) + φ(t) (its integral)
# --------------------------------------------------------------------------------------------

_T_MAX = 8.5
_T_STEP = 1.0 / 4096.0
_TABLES: dict = {}


def _tables():
    if not _TABLES:
        n = int(round(2 * _T_MAX / _T_STEP)) + 1
        t = -_T_MAX + _T_STEP * np.arange(n)
        phi_cdf = np.array([0.5 * math.erfc(-v / math.sqrt(2.0)) for v in t.tolist()])
        pdf = np.exp(-0.5 * t * t) / math.sqrt(2.0 * math.pi)
        psi = t * phi_cdf + pdf
        for name, tab in (("Phi", phi_cdf), ("Psi", psi)):
            _TABLES[name] = tab
            _TABLES["d" + name] = np.append(np.diff(tab), 0.0)
        _TABLES["n"] = n
    return _TABLES


def _lookup(name: str, t: np.ndarray) -> np.ndarray:
    tb = _tables()
    s = (np.clip(t, -_T_MAX, _T_MAX) + _T_MAX) * (1.0 / _T_STEP)
    i = s.astype(np.int64)
    np.minimum(i, tb["n"] - 2, out=i)
    f = s - i
    return tb[name][i] + f * tb["d" + name][i]


def norm_cdf(t) -> np.ndarray:
    """Φ(t), standard normal CDF, linear interpolation of a 1/4096 table (abs. error < 3e-9)."""
    return _lookup("Phi", np.asarray(t, dtype=float))


def psi1(t) -> np.ndarray:
    """Ψ1(t) = ∫_{-∞}^t Φ(s) ds = tΦ(t) + φ(t) (abs. error < 5e-9); Ψ1(t) = t beyond +8.5."""
    t = np.asarray(t, dtype=float)
    return _lookup("Psi", t) + np.maximum(t - _T_MAX, 0.0)


def bessel_j1(x) -> np.ndarray:
    """J1(x) = (1/π)∫_0^π cos(τ − x sin τ) dτ, trapezoid on an even periodic integrand (spectral)."""
    x = np.asarray(x, dtype=float)
    tau = np.linspace(0.0, math.pi, 257)
    w = np.full(tau.size, 1.0)
    w[0] = w[-1] = 0.5
    vals = np.cos(tau[None, :] - x.reshape(-1, 1) * np.sin(tau)[None, :])
    return ((vals * w).sum(axis=1) * (math.pi / 256) / math.pi).reshape(x.shape)


# --------------------------------------------------------------------------------------------
# Exact area of a disk ∩ axis-aligned rectangle
# --------------------------------------------------------------------------------------------


def _h_int(X, R, R2):
    """∫_{-R}^{X} sqrt(R² − t²) dt with X clipped to [−R, R]."""
    Xc = np.clip(X, -R, R)
    return 0.5 * (Xc * np.sqrt(np.maximum(R2 - Xc * Xc, 0.0)) + R2 * np.arcsin(Xc / R)) + 0.25 * math.pi * R2


def disk_corner_area(x, y, R):
    """Area of {X² + Y² ≤ R²} ∩ {X ≤ x} ∩ {Y ≤ y} (disk centred at the origin), exact, broadcasting."""
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    R = np.asarray(R, dtype=float)
    R2 = R * R
    ay = np.abs(y)
    a = np.sqrt(np.maximum(R2 - ay * ay, 0.0))
    hx = _h_int(x, R, R2)
    # for y >= 0: lower half-disk left of x, plus the part of the upper half below y left of x
    gpos = (hx + _h_int(np.minimum(x, -a), R, R2) + ay * np.clip(x + a, 0.0, 2.0 * a)
            + _h_int(np.maximum(x, a), R, R2) - _h_int(a, R, R2))
    return np.where(y >= 0, gpos, 2.0 * hx - gpos)


def disk_rect_area(cx, cy, R, x0, x1, y0, y1):
    """Exact area of the disk (centre (cx, cy), radius R) ∩ [x0, x1] × [y0, y1], broadcasting."""
    g = disk_corner_area
    return (g(x1 - cx, y1 - cy, R) - g(x0 - cx, y1 - cy, R)
            - g(x1 - cx, y0 - cy, R) + g(x0 - cx, y0 - cy, R))


# --------------------------------------------------------------------------------------------
# Geometry
# --------------------------------------------------------------------------------------------


def rot(theta: float) -> np.ndarray:
    """Rotation by θ in image coordinates (x right, y down): +θ turns +x toward +y (clockwise on screen)."""
    c, s = math.cos(theta), math.sin(theta)
    return np.array([[c, -s], [s, c]])


def tilt_matrix(theta_x: float, theta_y: float) -> np.ndarray:
    """Ry(θy)·Rx(θx) with Rx(θ) = [[1,0,0],[0,cos θ,−sin θ],[0,sin θ,cos θ]] (the +y side of the target
    goes farther from the camera for θx > 0) and Ry(θ) = [[cos θ,0,−sin θ],[0,1,0],[sin θ,0,cos θ]]
    (the +x side goes farther for θy > 0). Camera frame: x right, y down, z along the view."""
    cx, sx = math.cos(theta_x), math.sin(theta_x)
    cy, sy = math.cos(theta_y), math.sin(theta_y)
    Rx = np.array([[1.0, 0.0, 0.0], [0.0, cx, -sx], [0.0, sx, cx]])
    Ry = np.array([[cy, 0.0, -sy], [0.0, 1.0, 0.0], [sy, 0.0, cy]])
    return Ry @ Rx


class Camera:
    def __init__(self, spec: dict):
        self.W = int(spec["width"])
        self.H = int(spec["height"])
        self.scale = float(spec["scale_px_per_mm"])
        self.axis = np.array([(self.W - 1) / 2.0, (self.H - 1) / 2.0])
        self.r0 = 0.5 * math.hypot(self.W, self.H)
        eff = spec["effects"]
        self.k1 = float(eff["k1_per_px2"])
        self.psf = float(eff["psf_sigma_px"])
        self.vig = float(eff["vignetting_v"])
        self.fx, self.fy = (float(v) for v in eff["fill_factor"])
        # general Brown–Conrady (normalised by r0) about a centre offset from the axis
        self.k1n = self.k1 * self.r0 ** 2
        self.k2n = float(opt_effect(spec, "k2_norm"))
        self.p1n = float(opt_effect(spec, "p1_norm"))
        self.p2n = float(opt_effect(spec, "p2_norm"))
        self.dcentre = np.array([float(v) for v in opt_effect(spec, "distortion_centre_px")])
        # only k1 about the axis: the original code paths (byte-identical output)
        self.general_distortion = bool(self.k2n != 0 or self.p1n != 0 or self.p2n != 0
                                       or np.any(self.dcentre != 0))
        # pinhole perspective of a tilted and/or bowed target
        self.Z = float(opt_top(spec, "working_distance_mm"))
        self.theta_x = float(opt_effect(spec, "tilt_about_x_rad"))
        self.theta_y = float(opt_effect(spec, "tilt_about_y_rad"))
        self.bow = float(opt_effect(spec, "target_bow_per_mm"))
        self.saddle = float(opt_effect(spec, "target_saddle_per_mm"))
        # a target out of its plane: bowed and/or saddle-shaped (the depth depends on P)
        self.curved = bool(self.bow != 0 or self.saddle != 0)
        self.ramp = np.array([float(v) for v in opt_effect(spec, "lamp_ramp_per_px")])
        self.R3 = tilt_matrix(self.theta_x, self.theta_y)
        self.perspective_on = bool(self.theta_x != 0 or self.theta_y != 0 or self.curved)
        # the distortion must be monotonic over the frame (no fold-over): for k1 < 0, r(1 + k1 r²)
        # peaks at r = 1/sqrt(−3 k1) with the value (2/3)/sqrt(−3 k1)
        if self.k1 < 0 and 1.05 * self.r0 >= (2.0 / 3.0) / math.sqrt(-3.0 * self.k1):
            raise SpecError("k1 too strongly negative: the distortion folds over inside the frame")
        if self.general_distortion:
            self._check_fold_over()

    # ---- lens distortion --------------------------------------------------------------------

    def _brown(self, v: np.ndarray):
        """v: (..., 2) undistorted offsets from the distortion centre (px). Returns the distortion
        r0·(dxn, dyn) (px) and its Jacobian d(x_d)/d(x) = I + ∂(dxn, dyn)/∂qn, (..., 2, 2)."""
        q = v / self.r0
        qx, qy = q[..., 0], q[..., 1]
        r2 = qx * qx + qy * qy
        k1, k2, p1, p2 = self.k1n, self.k2n, self.p1n, self.p2n
        radial = k1 * r2 + k2 * r2 * r2
        drad = 2.0 * (k1 + 2.0 * k2 * r2)  # ∂radial/∂qx = qx·drad
        dxn = qx * radial + 2.0 * p1 * qx * qy + p2 * (r2 + 2.0 * qx * qx)
        dyn = qy * radial + p1 * (r2 + 2.0 * qy * qy) + 2.0 * p2 * qx * qy
        J = np.empty(q.shape + (2,))
        J[..., 0, 0] = 1.0 + radial + qx * qx * drad + 2.0 * p1 * qy + 6.0 * p2 * qx
        J[..., 0, 1] = qx * qy * drad + 2.0 * p1 * qx + 2.0 * p2 * qy
        J[..., 1, 0] = qx * qy * drad + 2.0 * p1 * qx + 2.0 * p2 * qy
        J[..., 1, 1] = 1.0 + radial + qy * qy * drad + 6.0 * p1 * qy + 2.0 * p2 * qx
        return self.r0 * np.stack([dxn, dyn], axis=-1), J

    def distort(self, u: np.ndarray) -> np.ndarray:
        """u: (..., 2) undistorted offsets from the axis (px) → distorted offsets."""
        if self.general_distortion:
            return u + self._brown(u - self.dcentre)[0]
        r2 = (u * u).sum(axis=-1, keepdims=True)
        return u * (1.0 + self.k1 * r2)

    def distort_with_det(self, u: np.ndarray):
        """Distorted offsets and det of the distortion's Jacobian (general model)."""
        D, J = self._brown(u - self.dcentre)
        det = J[..., 0, 0] * J[..., 1, 1] - J[..., 0, 1] * J[..., 1, 0]
        return u + D, det

    def _undistort_radius(self, rd: np.ndarray) -> np.ndarray:
        ru = rd.astype(float).copy()
        for _ in range(60):
            f = ru * (1 + self.k1 * ru * ru) - rd
            ru = ru - f / (1 + 3 * self.k1 * ru * ru)
        return ru

    def _undistort_general(self, ud: np.ndarray, check: bool = True) -> np.ndarray:
        """Newton on x + r0·D((x − e)/r0) = x_d (analytic 2x2 Jacobian), to |step| < 1e-10 px."""
        ud = np.asarray(ud, float)
        u = ud.copy()
        for _ in range(100):
            D, J = self._brown(u - self.dcentre)
            F = u + D - ud
            step = np.linalg.solve(J, F[..., None])[..., 0]
            u = u - step
            if float(np.abs(step).max(initial=0.0)) < 1e-10:
                break
        else:
            if check:
                raise SpecError("the lens distortion cannot be inverted over the frame (fold-over?)")
        return u

    def undistort(self, ud: np.ndarray) -> np.ndarray:
        if self.general_distortion:
            return self._undistort_general(ud)
        rd = np.sqrt((ud * ud).sum(axis=-1))
        ru = self._undistort_radius(rd)
        fac = np.where(rd > 0, ru / np.where(rd > 0, rd, 1.0), 1.0)
        return ud * fac[..., None]

    def _check_fold_over(self):
        """Refuse a distortion whose Jacobian determinant is ≤ 0.2 anywhere on a 41x41 grid of the
        frame (border included, 5 % beyond it), at the undistorted points of those image points."""
        n = 41
        xs = np.linspace(-0.5 - 0.05 * self.W, self.W - 0.5 + 0.05 * self.W, n)
        ys = np.linspace(-0.5 - 0.05 * self.H, self.H - 0.5 + 0.05 * self.H, n)
        X, Y = np.meshgrid(xs, ys)
        ud = np.stack([X.ravel(), Y.ravel()], axis=1) - self.axis
        try:
            uu = self._undistort_general(ud)
        except (SpecError, np.linalg.LinAlgError):
            raise SpecError("the lens distortion folds over inside the frame (no inverse)") from None
        back, det = self.distort_with_det(uu)
        if not np.all(np.isfinite(det)) or float(det.min()) <= 0.2 or float(np.abs(back - ud).max()) > 1e-6:
            raise SpecError(f"the lens distortion folds over inside the frame (min Jacobian determinant "
                            f"{float(np.nanmin(det)):.3g} <= 0.2)")

    # ---- perspective of a tilted / bowed target ----------------------------------------------

    def perspective(self, q: np.ndarray, P: np.ndarray, Minv: np.ndarray, jacobian: bool = True):
        """q: (n, 2) in-plane target points (mm) of a frame, P: (n, 2) their print coordinates (mm)
        for the bow, Minv = M⁻¹ (dP/dq). World W = Ry·Rx·(qx, qy, 0) + (0, 0, Z + κ|P|²/2); image
        offset u' = scale·Z·(Wx/Wz, Wy/Wz) (px). Returns u', Wz and the Jacobian d(u'/scale)/dq."""
        R = self.R3
        Wx = R[0, 0] * q[:, 0] + R[0, 1] * q[:, 1]
        Wy = R[1, 0] * q[:, 0] + R[1, 1] * q[:, 1]
        Wz = R[2, 0] * q[:, 0] + R[2, 1] * q[:, 1] + self.Z
        if self.bow != 0:
            Wz = Wz + 0.5 * self.bow * (P * P).sum(axis=1)
        if self.saddle != 0:
            Wz = Wz + 0.5 * self.saddle * (P[:, 0] ** 2 - P[:, 1] ** 2)
        f = self.Z / Wz
        u2 = self.scale * np.stack([f * Wx, f * Wy], axis=1)
        if not jacobian:
            return u2, Wz, None
        dWz = np.tile(R[2, :2], (q.shape[0], 1))
        if self.bow != 0:
            dWz = dWz + self.bow * (P @ Minv)  # ∂z/∂q_j = κ Σ_i P_i (M⁻¹)_ij
        if self.saddle != 0:
            # ∂z/∂q_j = κs Σ_i s_i P_i (M⁻¹)_ij, s = (1, −1)
            dWz = dWz + self.saddle * ((P * np.array([1.0, -1.0])) @ Minv)
        J = np.empty((q.shape[0], 2, 2))
        for row, Wc in ((0, Wx), (1, Wy)):
            for j in range(2):
                J[:, row, j] = f * (R[row, j] - Wc / Wz * dWz[:, j])
        return u2, Wz, J

    def unproject(self, u2: np.ndarray, fr: "Frame") -> np.ndarray:
        """Inverse of the perspective for frame fr: undistorted image offsets u' (px) → in-plane
        offsets u = scale·q (px). Flat target: exact ray–plane intersection; bowed or saddle-shaped, Newton
        iterations from there (analytic Jacobian) to 1e-9 px."""
        R = self.R3
        n = R[:, 2]  # the plane's normal
        ray = np.stack([u2[:, 0] / (self.scale * self.Z), u2[:, 1] / (self.scale * self.Z),
                        np.ones(u2.shape[0])], axis=1)
        den = ray @ n
        if np.any(den * n[2] <= 0):
            raise SpecError("the tilted target is not in front of the camera over the whole frame")
        t = self.Z * n[2] / den
        Wrel = t[:, None] * ray - np.array([0.0, 0.0, self.Z])
        q = Wrel @ R[:, :2]  # in-plane coordinates: Rᵀ(W − Z e_z), first two
        if self.curved:
            Minv = np.linalg.inv(fr.M)
            for _ in range(100):
                P = q @ Minv.T - fr.d / self.scale
                got, Wz, J = self.perspective(q, P, Minv)
                res = got - u2
                if float(np.abs(res).max(initial=0.0)) < 1e-9:
                    break
                q = q - np.linalg.solve(self.scale * J, res[..., None])[..., 0]
            else:
                raise SpecError("cannot invert the bowed target's projection (bow too strong?)")
            if np.any(Wz <= 0):
                raise SpecError("the bowed target is not in front of the camera over the whole frame")
        return self.scale * q

    def tilt_first_order(self):
        """a = tan θy/(Z·scale), b = tan θx/(Z·scale) (1/px): first-order perspective coefficients."""
        return (math.tan(self.theta_y) / (self.Z * self.scale), math.tan(self.theta_x) / (self.Z * self.scale))

    def vignetting(self) -> np.ndarray:
        if self.vig == 0:
            return None
        x = np.arange(self.W) - self.axis[0]
        y = np.arange(self.H) - self.axis[1]
        r2 = y[:, None] ** 2 + x[None, :] ** 2
        return 1.0 - self.vig * r2 / (self.r0 ** 2)


class Frame:
    """Where the print sits in one frame: undistorted offset from the axis u = M (scale·P + d)."""

    def __init__(self, name: str, kind: str, M: np.ndarray, d_px: np.ndarray, gain: float, ds: float):
        self.name, self.kind = name, kind
        self.M = np.asarray(M, float)
        self.d = np.asarray(d_px, float)
        self.gain = float(gain)
        self.lin = 1.0 + float(ds)  # linear magnification relative to the reference

    def print_to_undistorted(self, P_mm: np.ndarray, scale: float) -> np.ndarray:
        return (scale * P_mm + self.d) @ self.M.T

    def undistorted_to_print(self, u: np.ndarray, scale: float) -> np.ndarray:
        return (u @ np.linalg.inv(self.M).T - self.d) / scale


# --------------------------------------------------------------------------------------------
# The print
# --------------------------------------------------------------------------------------------


def _seed_seq(seed: int, *key) -> np.random.SeedSequence:
    parts = []
    for k in key:
        parts.append(int(k) if isinstance(k, int) else zlib.crc32(str(k).encode()))
    return np.random.SeedSequence(entropy=seed, spawn_key=tuple(parts))


class CellIndex:
    """Points binned into square cells, for neighbour queries within one cell size."""

    def __init__(self, x, y, cell, x0, y0):
        self.cell, self.x0, self.y0 = cell, x0, y0
        ix = np.floor((x - x0) / cell).astype(np.int64)
        iy = np.floor((y - y0) / cell).astype(np.int64)
        self.nx, self.ny = int(ix.max()) + 1, int(iy.max()) + 1
        key = iy * self.nx + ix
        order = np.argsort(key, kind="stable")
        counts = np.bincount(key, minlength=self.nx * self.ny)
        m = max(int(counts.max()), 1)
        starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
        rank = np.arange(key.size) - starts[key[order]]
        tab = np.full((self.ny + 2, self.nx + 2, m), -1, dtype=np.int64)
        tab[iy[order] + 1, ix[order] + 1, rank] = order
        self.tab = tab

    def candidates(self, qx, qy) -> np.ndarray:
        ix = np.clip(np.floor((qx - self.x0) / self.cell).astype(np.int64), -1, self.nx) + 1
        iy = np.clip(np.floor((qy - self.y0) / self.cell).astype(np.int64), -1, self.ny) + 1
        out = []
        for dy in (-1, 0, 1):
            for dx in (-1, 0, 1):
                jy = np.clip(iy + dy, 0, self.ny + 1)
                jx = np.clip(ix + dx, 0, self.nx + 1)
                out.append(self.tab[jy, jx])
        return np.concatenate(out, axis=1)


def _nearest_neighbour(x, y, spacing):
    cell = 3.0 * spacing
    idx = CellIndex(x, y, cell, x.min() - 1e-9, y.min() - 1e-9)
    nn = np.full(x.size, np.inf)
    for lo in range(0, x.size, 20000):
        q = slice(lo, min(lo + 20000, x.size))
        cand = idx.candidates(x[q], y[q])
        valid = (cand >= 0) & (cand != np.arange(lo, q.stop)[:, None])
        cc = np.where(valid, cand, 0)
        d2 = (x[cc] - x[q, None]) ** 2 + (y[cc] - y[q, None]) ** 2
        d2 = np.where(valid, d2, np.inf)
        nn[q] = np.sqrt(d2.min(axis=1))
    return nn


def _dart_disks(rng, x0, x1, y0, y1, n_target, dmin, max_rounds=800):
    """Random hard-core point set (no two centres closer than dmin) with exactly n_target points.

    Parallel random sequential adsorption on cells of side dmin/√2 (≤ 1 point per cell): each
    round puts one uniform candidate in every empty cell, drops candidates within dmin of an
    accepted point, and of the conflicting candidates keeps only those with the highest random
    priority among their conflicts; the last round keeps a random subset to hit n_target.
    """
    h = dmin / math.sqrt(2.0)
    nx = int(math.ceil((x1 - x0) / h))
    ny = int(math.ceil((y1 - y0) / h))
    PX = np.full((ny + 4, nx + 4), np.nan)
    PY = np.full((ny + 4, nx + 4), np.nan)
    d2min = dmin * dmin
    count = 0
    idle = 0
    offsets = [(dy, dx) for dy in range(-2, 3) for dx in range(-2, 3)]
    for _ in range(max_rounds):
        if count >= n_target:
            break
        ey, ex = np.nonzero(np.isnan(PX[2:-2, 2:-2]))
        if ey.size == 0:
            break
        cxs = x0 + (ex + rng.random(ey.size)) * h
        cys = y0 + (ey + rng.random(ey.size)) * h
        ok = (cxs < x1) & (cys < y1)
        for dy, dx in offsets:
            if dy == 0 and dx == 0:
                continue
            nxv = PX[ey + 2 + dy, ex + 2 + dx]
            nyv = PY[ey + 2 + dy, ex + 2 + dx]
            ok &= ~(((nxv - cxs) ** 2 + (nyv - cys) ** 2) < d2min)
        ey, ex, cxs, cys = ey[ok], ex[ok], cxs[ok], cys[ok]
        if ey.size:
            CX = np.full(PX.shape, np.nan)
            CY = np.full(PX.shape, np.nan)
            PR = np.full(PX.shape, -1.0)
            pri = rng.random(ey.size)
            CX[ey + 2, ex + 2] = cxs
            CY[ey + 2, ex + 2] = cys
            PR[ey + 2, ex + 2] = pri
            keep = np.ones(ey.size, bool)
            for dy, dx in offsets:
                if dy == 0 and dx == 0:
                    continue
                nxv = CX[ey + 2 + dy, ex + 2 + dx]
                nyv = CY[ey + 2 + dy, ex + 2 + dx]
                npr = PR[ey + 2 + dy, ex + 2 + dx]
                keep &= ~((((nxv - cxs) ** 2 + (nyv - cys) ** 2) < d2min) & (npr > pri))
            ey, ex, cxs, cys = ey[keep], ex[keep], cxs[keep], cys[keep]
        if count + ey.size > n_target:
            sel = rng.permutation(ey.size)[: n_target - count]
            ey, ex, cxs, cys = ey[sel], ex[sel], cxs[sel], cys[sel]
        PX[ey + 2, ex + 2] = cxs
        PY[ey + 2, ex + 2] = cys
        count += ey.size
        idle = idle + 1 if ey.size == 0 else 0
        if idle >= 40:
            break
    if count < n_target:
        raise SpecError(
            f"cannot place {n_target} non-overlapping disks (reached {count}): density too high "
            f"for minimum centre distance {dmin:.4g} mm; use placement 'jittered_grid', a larger "
            f"dot_spacing_mm or a smaller diameter")
    m = ~np.isnan(PX)
    xs, ys = PX[m], PY[m]
    order = rng.permutation(xs.size)
    return xs[order], ys[order]


class Print:
    """A speckle print: dot centres (mm), diameters (mm), profile, contrast, edge softness."""

    def __init__(self, pat: dict, seed: int, bounds, render: dict):
        self.label = pat["label"]
        self.profile = pat["profile"]
        self.d_nom = float(pat["dot_diameter_mm"])
        self.s_nom = float(pat["dot_spacing_mm"])
        self.c = float(pat["contrast"])
        self.cv = float(pat["diameter_cv"])
        self.soft = float(pat["edge_softness_mm"])
        self.placement = pat["placement"]
        self.bounds = tuple(float(b) for b in bounds)  # x0, x1, y0, y1 (mm)
        base_seed = seed if "seed" not in pat else int(pat["seed"])
        rng = np.random.default_rng(_seed_seq(base_seed, 1, self.label))
        x0, x1, y0, y1 = self.bounds
        area = (x1 - x0) * (y1 - y0)
        rho = 1.0 / self.s_nom ** 2
        self.min_gap = None
        self.jitter = None
        if self.profile == "gaussian":
            n = int(rng.poisson(rho * area))
            self.x = x0 + (x1 - x0) * rng.random(n)
            self.y = y0 + (y1 - y0) * rng.random(n)
            self.d = self._diameters(rng, n)
        else:
            n_target = int(round(rho * area))
            diam = self._diameters(rng, n_target)
            gap = float(pat["min_gap_mm"])
            self.min_gap = gap
            dmin = float(diam.max()) + gap
            if self.placement == "dart":
                self.x, self.y = _dart_disks(rng, x0, x1, y0, y1, n_target, dmin)
                self.d = diam
            else:
                s = self.s_nom
                if s <= dmin:
                    raise SpecError(f"pattern {self.label}: jittered grid pitch {s} mm <= diameter + gap {dmin} mm")
                jmax = 0.5 * (s - dmin)
                j = min(float(pat.get("jitter_mm", jmax)), jmax)
                self.jitter = j
                ox, oy = rng.random(2) * s
                gx = np.arange(x0 - s + ox, x1, s)
                gy = np.arange(y0 - s + oy, y1, s)
                GX, GY = np.meshgrid(gx, gy)
                GX = GX.ravel() + rng.uniform(-j, j, GX.size)
                GY = GY.ravel() + rng.uniform(-j, j, GY.size)
                keep = (GX >= x0) & (GX < x1) & (GY >= y0) & (GY < y1)
                self.x, self.y = GX[keep], GY[keep]
                self.d = self._diameters(rng, self.x.size)
        self.render = render

    def _diameters(self, rng, n):
        if self.cv <= 0:
            return np.full(n, self.d_nom)
        z = np.clip(rng.standard_normal(n), -3.0, 3.0)
        return self.d_nom * np.maximum(1.0 + self.cv * z, 0.1)

    # the print's reflectance deficit "volume" per dot (mm²): ∫ deficit dA
    def dot_volume_mm2(self):
        if self.profile == "gaussian":
            s0 = self.d / FWHM_PER_SIGMA
            return self.c * 2 * math.pi * s0 ** 2
        return self.c * math.pi * (self.d / 2) ** 2

    def transfer(self, f):
        """Signed transfer function of the print's own (volume-weighted mean) dot profile at f (cyc/mm)."""
        f = np.asarray(f, float)
        vol = self.dot_volume_mm2()
        soft = np.exp(-2 * math.pi ** 2 * self.soft ** 2 * f ** 2)
        # volume-weighted diameters binned into ≤ 256 bins (each bin at its volume-weighted mean)
        d = self.d
        lo, hi = float(d.min()), float(d.max())
        if hi > lo:
            b = np.minimum(((d - lo) / (hi - lo) * 256).astype(int), 255)
            vb = np.bincount(b, weights=vol, minlength=256)
            db = np.bincount(b, weights=vol * d, minlength=256)
            m = vb > 0
            vol, d = vb[m], db[m] / vb[m]
        else:
            vol, d = np.array([vol.sum()]), np.array([lo])
        if self.profile == "gaussian":
            s0 = d / FWHM_PER_SIGMA
            per = np.exp(-2 * math.pi ** 2 * s0[:, None] ** 2 * f[None, :] ** 2)
        else:
            z = math.pi * d[:, None] * f[None, :]
            zz = np.where(z > 0, z, 1.0)
            per = np.where(z > 0, 2 * bessel_j1(zz) / zz, 1.0)
        return soft * (vol[:, None] * per).sum(axis=0) / vol.sum()

    def stats(self, inner_bounds, scale):
        x0, x1, y0, y1 = self.bounds
        area = (x1 - x0) * (y1 - y0)
        nn = _nearest_neighbour(self.x, self.y, self.s_nom) if self.x.size > 1 else np.array([np.nan])
        out = {
            "n_dots": int(self.x.size),
            "field_mm": {"x0": x0, "x1": x1, "y0": y0, "y1": y1},
            "field_area_mm2": area,
            "density_per_mm2": self.x.size / area,
            "nominal_density_per_mm2": 1.0 / self.s_nom ** 2,
            "effective_spacing_mm": math.sqrt(area / max(self.x.size, 1)),
            "diameter_mm": {"mean": float(self.d.mean()), "std": float(self.d.std()),
                            "min": float(self.d.min()), "max": float(self.d.max())},
            "nearest_neighbour_mm": {"mean": float(nn.mean()), "min": float(nn.min()),
                                     "median": float(np.median(nn))},
            "mean_deficit": float(self.dot_volume_mm2().sum() / area),
        }
        if self.profile == "disk":
            out["area_fraction_covered"] = float((math.pi * (self.d / 2) ** 2).sum() / area)
            # smallest edge-to-edge gap between neighbouring disks
            out["min_centre_distance_mm"] = float(nn.min())
            out["min_gap_setting_mm"] = self.min_gap
            out["placement"] = self.placement
            if self.jitter is not None:
                out["jitter_mm"] = self.jitter
        else:
            out["placement"] = "poisson"
            out.update(self._overlap_stats(inner_bounds))
        return out

    def _overlap_stats(self, inner):
        """Monte Carlo over the print (within the frame's field): Σ deficits at random points."""
        n = int(self.render.get("overlap_samples", 20000))
        if n <= 0 or self.x.size == 0:
            return {}
        rng = np.random.default_rng(_seed_seq(0, 99, self.label))
        s0 = np.sqrt((self.d / FWHM_PER_SIGMA) ** 2 + self.soft ** 2)
        amp = self.c * (self.d / FWHM_PER_SIGMA) ** 2 / s0 ** 2
        cell = 6.0 * float(s0.max())
        x0, x1, y0, y1 = inner
        qx = x0 + (x1 - x0) * rng.random(n)
        qy = y0 + (y1 - y0) * rng.random(n)
        idx = CellIndex(self.x, self.y, cell, self.bounds[0] - 1e-9, self.bounds[2] - 1e-9)
        total = np.zeros(n)
        for lo in range(0, n, 5000):
            q = slice(lo, min(lo + 5000, n))
            cand = idx.candidates(qx[q], qy[q])
            valid = cand >= 0
            cc = np.where(valid, cand, 0)
            r2 = (self.x[cc] - qx[q, None]) ** 2 + (self.y[cc] - qy[q, None]) ** 2
            v = amp[cc] * np.exp(-0.5 * r2 / s0[cc] ** 2)
            total[q] = np.where(valid, v, 0.0).sum(axis=1)
        return {
            "print_deficit_sum_samples": n,
            "print_fraction_reflectance_below_0": float((total > 1).mean()),
            "print_max_deficit_sum": float(total.max()),
            "print_mean_deficit_sum": float(total.mean()),
        }


# --------------------------------------------------------------------------------------------
# Rendering
# --------------------------------------------------------------------------------------------


class _Accumulator:
    """Deficit image with a margin, accumulating per-dot patches with np.bincount."""

    def __init__(self, W, H, pad):
        self.W, self.H, self.pad = W, H, pad
        self.Wp, self.Hp = W + 2 * pad, H + 2 * pad
        self.img = np.zeros(self.Hp * self.Wp)

    def add(self, x0, y0, patch):
        """patch: (n, Ky, Kx) for dots whose window starts at pixel (x0, y0) (may be negative)."""
        n, Ky, Kx = patch.shape
        rows = (y0 + self.pad)[:, None] + np.arange(Ky)[None, :]
        cols = (x0 + self.pad)[:, None] + np.arange(Kx)[None, :]
        idx = rows[:, :, None] * self.Wp + cols[:, None, :]
        lo = int(idx.min())
        hi = int(idx.max()) + 1
        self.img[lo:hi] += np.bincount((idx - lo).ravel(), weights=patch.ravel(), minlength=hi - lo)

    def image(self):
        p = self.pad
        return self.img.reshape(self.Hp, self.Wp)[p:p + self.H, p:p + self.W]


def _chunks(order, per_dot, budget=3_000_000):
    n = max(1, budget // max(per_dot, 1))
    for lo in range(0, order.size, n):
        yield order[lo:lo + n]


def _groups_by(values, rel=0.08):
    """Split indices into groups of similar value (for window sizes), each sorted later by y."""
    v = np.asarray(values)
    if v.size == 0:
        return []
    lo, hi = float(v.min()), float(v.max())
    if hi <= lo * (1 + rel):
        return [np.arange(v.size)]
    nb = int(math.ceil(math.log(hi / lo) / math.log(1 + rel)))
    b = np.minimum((np.log(v / lo) / math.log(1 + rel)).astype(int), nb - 1)
    return [np.nonzero(b == k)[0] for k in range(nb) if np.any(b == k)]


def _render_gaussian(acc, cx, cy, sig, amp, fx, fy, wsig):
    """Σ amp·exp(−r²/2σ²) averaged exactly over each pixel's fx × fy aperture (separable erf)."""
    root2pi = math.sqrt(2 * math.pi)
    for grp in _groups_by(sig):
        smax = float(sig[grp].max())
        half = int(math.ceil(wsig * smax + 0.5 * max(fx, fy) + 1))
        K = 2 * half + 1
        order = grp[np.argsort(cy[grp], kind="stable")]
        for ch in _chunks(order, K * K):
            x0 = np.rint(cx[ch]).astype(np.int64) - half
            y0 = np.rint(cy[ch]).astype(np.int64) - half
            s = sig[ch][:, None]
            k = np.arange(K)[None, :]
            px = x0[:, None] + k - cx[ch][:, None]
            py = y0[:, None] + k - cy[ch][:, None]
            X = (root2pi / fx) * s * (norm_cdf((px + 0.5 * fx) / s) - norm_cdf((px - 0.5 * fx) / s))
            Y = (root2pi / fy) * s * (norm_cdf((py + 0.5 * fy) / s) - norm_cdf((py - 0.5 * fy) / s))
            Y *= amp[ch][:, None]
            acc.add(x0, y0, Y[:, :, None] * X[:, None, :])


def _render_disks_exact(acc, cx, cy, R, depth, fx, fy):
    """Hard disks, no blur: exact area of disk ∩ pixel aperture (analytic), times depth."""
    for grp in _groups_by(R):
        rmax = float(R[grp].max())
        half = int(math.ceil(rmax + 0.5 * max(fx, fy) + 1))
        K = 2 * half + 1
        order = grp[np.argsort(cy[grp], kind="stable")]
        for ch in _chunks(order, 4 * (K + 1) * (K + 1) // 3 + 1):
            x0 = np.rint(cx[ch]).astype(np.int64) - half
            y0 = np.rint(cy[ch]).astype(np.int64) - half
            r = R[ch][:, None, None]
            if fx == 1.0 and fy == 1.0:
                e = np.arange(K + 1)[None, :] - 0.5
                ex = (x0[:, None] + e - cx[ch][:, None])[:, None, :]
                ey = (y0[:, None] + e - cy[ch][:, None])[:, :, None]
                G = disk_corner_area(ex, ey, r)
                area = G[:, 1:, 1:] - G[:, 1:, :-1] - G[:, :-1, 1:] + G[:, :-1, :-1]
            else:
                k = np.arange(K)[None, :]
                px = (x0[:, None] + k - cx[ch][:, None])[:, None, :]
                py = (y0[:, None] + k - cy[ch][:, None])[:, :, None]
                g = disk_corner_area
                xl, xr = px - 0.5 * fx, px + 0.5 * fx
                yt, yb = py - 0.5 * fy, py + 0.5 * fy
                area = g(xr, yb, r) - g(xl, yb, r) - g(xr, yt, r) + g(xl, yt, r)
            acc.add(x0, y0, area * (depth[ch][:, None, None] / (fx * fy)))


def _edge_response(p0_minus_e, sig, f, K):
    """E(e)[k] = (1/f)∫_{p_k−f/2}^{p_k+f/2} Φ((s−e)/σ) ds = (σ/f)[Ψ1((p_k−e+f/2)/σ) − Ψ1((p_k−e−f/2)/σ)]
    for the K pixels p_k = p_0 + k: a step edge at e blurred by a Gaussian σ and averaged over an
    aperture of width f (exact). The interval [a, b] is then E(a) − E(b).
    p0_minus_e: (..., 1) array of p_0 − e; sig broadcastable to it."""
    k = np.arange(K + 1 if f == 1.0 else K)
    if f == 1.0:  # neighbouring apertures share their edges: K + 1 evaluations instead of 2K
        q = psi1((p0_minus_e - 0.5 + k) / sig)
        return sig * (q[..., 1:] - q[..., :-1])
    pe = p0_minus_e + k
    return (sig / f) * (psi1((pe + 0.5 * f) / sig) - psi1((pe - 0.5 * f) / sig))


def _render_disks_blurred(acc, cx, cy, R, depth, sig, fx, fy, ss, wsig):
    """Disks blurred by a Gaussian σ (PSF ⊕ print edge softness), over the pixel aperture.

    Each disk is cut into n = ceil(π·R·ss) horizontal strips with boundaries y_k = −R cos(πk/n)
    (thin near the poles where the chord changes fast; every strip ≤ 1/ss px high); each strip
    is replaced by the rectangle of the same height and the same (exact) area, centred on the
    disk's vertical axis. A rectangle blurred by a Gaussian and integrated over a rectangular
    aperture is exactly separable: (x-profile) ⊗ (y-profile), each a difference of Ψ1 terms.
    The only approximation is this staircase: area and centroid exact, error O(1/ss²) in the
    pixel values (1.5e-4 of the depth for R = 2.5 px, σ = 0.6 px, ss = 8; see selfcheck.py).
    """
    for grp in _groups_by(R + 3 * sig):
        rmax = float(R[grp].max())
        smax = float(sig[grp].max())
        ns = max(2, int(math.ceil(math.pi * rmax * ss)))
        half = int(math.ceil(rmax + wsig * smax + 0.5 * max(fx, fy) + 1))
        K = 2 * half + 1
        order = grp[np.argsort(cy[grp], kind="stable")]
        for ch in _chunks(order, 3 * ns * K + K * K):
            x0 = np.rint(cx[ch]).astype(np.int64) - half
            y0 = np.rint(cy[ch]).astype(np.int64) - half
            r = R[ch][:, None]
            s = sig[ch][:, None, None]
            frac = -np.cos(np.linspace(0.0, math.pi, ns + 1))[None, :]
            yb = r * frac  # strip boundaries relative to the centre, (n, ns+1)
            Hc = _h_int(yb, r, r * r)
            strip_area = 2.0 * np.diff(Hc, axis=1)  # (n, ns)
            hgt = np.diff(yb, axis=1)
            w = strip_area / (2.0 * hgt)  # half-width of the equal-area rectangle
            px0 = (x0 - cx[ch])[:, None, None]  # first window column − centre, (n, 1, 1)
            py0 = (y0 - cy[ch])[:, None, None]
            wk = w[:, :, None]
            X = _edge_response(px0 + wk, s, fx, K) - _edge_response(px0 - wk, s, fx, K)  # (n, ns, K)
            Ey = _edge_response(py0 - yb[:, :, None], s, fy, K)  # (n, ns+1, K)
            Y = Ey[:, :-1, :] - Ey[:, 1:, :]  # (n, ns, K)
            patch = np.matmul(np.transpose(Y, (0, 2, 1)), X)  # (n, Ky, Kx)
            patch *= depth[ch][:, None, None]
            acc.add(x0, y0, patch)


def render_irradiance(cam: Camera, pr: Print, fr: Frame, render: dict):
    """Noise-free irradiance as a fraction of white at the centre (before ADC), and diagnostics."""
    t0 = time.perf_counter()
    P = np.stack([pr.x, pr.y], axis=1)
    u = fr.print_to_undistorted(P, cam.scale)
    mag_p = None
    if cam.perspective_on:
        # tilted / bowed target through the pinhole; the dot's areal magnification sqrt(det J)
        Minv = np.linalg.inv(fr.M)
        u, Wz, Jt = cam.perspective(u / cam.scale, P, Minv)
        if np.any(Wz <= 0):
            raise SpecError("part of the target lies behind the camera")
        mag_p = np.sqrt(np.maximum(Jt[:, 0, 0] * Jt[:, 1, 1] - Jt[:, 0, 1] * Jt[:, 1, 0], 1e-12))
    if cam.general_distortion:
        # Brown–Conrady: the dot's local (areal) magnification sqrt(det J) of the distortion
        ud, det = cam.distort_with_det(u)
        xy = cam.axis + ud
        mag = np.sqrt(np.maximum(det, 1e-6))
    else:
        r2 = (u * u).sum(axis=1)
        xy = cam.axis + u * (1.0 + cam.k1 * r2)[:, None]
        # local magnification of the distortion: radial 1+3k1r², tangential 1+k1r²; geometric mean
        mag = np.sqrt(np.maximum((1 + 3 * cam.k1 * r2) * (1 + cam.k1 * r2), 1e-6))
    if mag_p is not None:
        mag = mag * mag_p
    lin = cam.scale * fr.lin * mag  # px per mm locally
    wsig = float(render["window_sigmas"])
    if pr.profile == "gaussian":
        s0 = pr.d / FWHM_PER_SIGMA
        s_img = lin * np.sqrt(s0 ** 2 + pr.soft ** 2)
        sig = np.sqrt(s_img ** 2 + cam.psf ** 2)
        vol = pr.c * 2 * math.pi * (lin * s0) ** 2  # ∫ deficit (px²), conserved by every blur
        amp = vol / (2 * math.pi * sig ** 2)
        reach = wsig * sig + 2
    else:
        R = 0.5 * pr.d * lin
        sig = np.sqrt((pr.soft * lin) ** 2 + cam.psf ** 2)
        reach = R + wsig * sig + 2
    keep = ((xy[:, 0] > -reach) & (xy[:, 0] < cam.W - 1 + reach)
            & (xy[:, 1] > -reach) & (xy[:, 1] < cam.H - 1 + reach))
    cx, cy = xy[keep, 0], xy[keep, 1]
    pad = int(math.ceil(2 * float(reach.max()) + 4)) if reach.size else 4
    acc = _Accumulator(cam.W, cam.H, pad)
    method = None
    if pr.profile == "gaussian":
        _render_gaussian(acc, cx, cy, sig[keep], amp[keep], cam.fx, cam.fy, wsig)
        method = "gaussian-exact-erf"
    elif sig.size == 0 or float(sig.max()) <= 1e-9:
        _render_disks_exact(acc, cx, cy, R[keep], np.full(cx.size, pr.c), cam.fx, cam.fy)
        method = "disk-exact-area"
    else:
        ss = int(render["disk_supersample"])
        _render_disks_blurred(acc, cx, cy, R[keep], np.full(cx.size, pr.c), sig[keep],
                              cam.fx, cam.fy, ss, wsig)
        method = f"disk-strips-ss{ss}"
    refl = 1.0 - acc.image()
    n_neg = int((refl < 0).sum())
    min_refl = float(refl.min())
    np.maximum(refl, 0.0, out=refl)
    V = cam.vignetting()
    if V is not None:
        refl *= V
    if fr.gain != 1.0:
        refl *= fr.gain
    if fr.kind == "deformed" and np.any(cam.ramp != 0):
        # a lamp that drifted after the reference: the moved frames lit with a linear ramp
        x = np.arange(cam.W) - cam.axis[0]
        y = np.arange(cam.H) - cam.axis[1]
        refl *= 1.0 + cam.ramp[0] * x[None, :] + cam.ramp[1] * y[:, None]
    diag = {"render_method": method, "dots_rendered": int(cx.size),
            "pixels_clipped_below_0": n_neg, "min_reflectance_before_clip": min_refl,
            "render_seconds": round(time.perf_counter() - t0, 3)}
    return refl, diag


def expose(irr: np.ndarray, spec: dict, rng: np.random.Generator):
    """Irradiance (fraction of white) → DN: Poisson electrons, Gaussian read noise, offset, round, clip."""
    white = float(spec["white_level_dn"])
    g = spec["gain_e_per_dn"]
    mean_dn = white * irr
    if spec["noise"]:
        if g is not None:
            dn = rng.poisson(mean_dn * float(g)) / float(g)
        else:
            dn = mean_dn.copy()
        rn = float(spec["read_noise_dn"])
        if rn > 0:
            dn += rng.normal(0.0, rn, dn.shape)
    else:
        dn = mean_dn.copy()
    dn += float(spec["dark_offset_dn"])
    full = 2 ** spec["bit_depth"] - 1
    dn = np.rint(dn)
    n_sat = int((dn > full).sum())
    n_zero = int((dn < 0).sum())
    np.clip(dn, 0, full, out=dn)
    dtype = np.uint16 if spec["bit_depth"] == 16 else np.uint8
    return dn.astype(dtype), {"pixels_saturated": n_sat, "pixels_clipped_at_0": n_zero}


def read_out(irr: np.ndarray, spec: dict, rng: np.random.Generator, ro: dict):
    """The camera's own read-out of one frame. Per axis a block of b·d sensor pixels gives one
    output pixel: the first b pixels of the block binned (decimation d keeps the first pixel of
    every d). Digital binning: every sensor pixel exposed and digitised on its own (`expose`:
    shot noise, read noise, ADC), then averaged or summed and rounded. Charge binning: the
    block's mean electrons summed, one Poisson draw and one read noise for the sum, then divided
    by the pixel count for an average, offset, rounded. A partial block at an edge is dropped."""
    bx, by = ro.get("binning", [1, 1])
    dx, dy = ro.get("decimation", [1, 1])
    kx, ky = bx * dx, by * dy
    H, W = irr.shape
    oh, ow = H // ky, W // kx
    blocks = irr[: oh * ky, : ow * kx].reshape(oh, ky, ow, kx)[:, :by, :, :bx]
    n = bx * by
    average = ro.get("value", "average") == "average"
    full = 2 ** spec["bit_depth"] - 1
    if ro.get("domain", "digital") == "digital" or n == 1:
        dn, _ = expose(blocks, spec, rng)
        dn = dn.astype(np.float64).sum(axis=(1, 3))
        if average:
            dn /= n
    else:
        white = float(spec["white_level_dn"])
        g = spec["gain_e_per_dn"]
        mean_dn = white * blocks.sum(axis=(1, 3))
        if spec["noise"]:
            dn = rng.poisson(mean_dn * float(g)) / float(g) if g is not None else mean_dn.copy()
            rn = float(spec["read_noise_dn"])
            if rn > 0:
                dn += rng.normal(0.0, rn, dn.shape)
        else:
            dn = mean_dn.copy()
        if average:
            dn /= n
        dn += float(spec["dark_offset_dn"])
    dn = np.clip(np.rint(dn), 0, full)
    return dn.astype(np.uint16 if spec["bit_depth"] == 16 else np.uint8)


def capture_mode(ro: dict) -> dict:
    """The manifest's `capture` of a read-out (ffdic-dataset/1: per axis a bin or a decimation)."""
    value = ro.get("value", "average")

    def axis(i):
        d = ro.get("decimation", [1, 1])[i]
        if d > 1:
            return {"kind": "decimate", "factor": d}
        return {"kind": "bin", "factor": ro.get("binning", [1, 1])[i], "mode": value}

    x, y = axis(0), axis(1)
    bins = any(a["kind"] == "bin" and a["factor"] > 1 for a in (x, y))
    fill = 1.0
    for a in (x, y):
        fill *= 1.0 if a["kind"] == "bin" else 1.0 / a["factor"]
    return {"name": ro["name"], "x": x, "y": y,
            "binning_domain": ro.get("domain", "digital") if bins else None,
            "equivalent_preset": None, "fill_factor": fill}


def _readout_stem(ro: dict) -> str:
    return re.sub(r"[^A-Za-z0-9_.+-]", "-", ro["name"])


def _readout_file(ro: dict, fname: str) -> str:
    return _readout_stem(ro) + "_" + fname


def write_tiff(path: Path, img: np.ndarray):
    tifffile.imwrite(path, img, photometric="minisblack", byteorder="<", compression=None)


# --------------------------------------------------------------------------------------------
# Runs, stage model
# --------------------------------------------------------------------------------------------


def plan_runs(spec: dict):
    """Every run: id, pattern label, commanded move, file names, per-run effect values."""
    eff = spec["effects"]
    runs = []
    for p in spec["patterns"]:
        lab = p["label"]
        entries = []
        for m in spec["moves"]:
            if "patterns" in m and lab not in m["patterns"]:
                continue
            entries.append((m["id"], float(m["dx_mm"]), float(m["dy_mm"]), m))
        for s in spec["step_series"]:
            if "patterns" in s and lab not in s["patterns"]:
                continue
            for k in range(1, s["count"] + 1):
                entries.append((f"{s['id']}{k}", k * float(s["dx_step_mm"]), k * float(s["dy_step_mm"]), s))
        for mid, dx, dy, src in entries:
            r = {"id": f"{lab}-{mid}", "pattern": lab, "move_id": mid,
                 "reference": f"{lab}_ref.tif", "deformed": f"{lab}_{mid}.tif",
                 "commanded_mm": [dx, dy]}
            for key in _PER_MOVE_OVERRIDES:
                r[key] = float(src.get(key, eff[key]))
            runs.append(r)
    ids = [r["id"] for r in runs]
    if len(set(ids)) != len(ids):
        raise SpecError("run ids are not unique (a move id collides with a step-series id)")
    files = [r["deformed"] for r in runs]
    if len(set(files)) != len(files):
        raise SpecError("deformed file names are not unique")
    unknown = set(spec["stage"]["per_run_offsets_px"]) - set(ids)
    if unknown:
        raise SpecError(f"stage.per_run_offsets_px names unknown runs: {sorted(unknown)}")
    return runs


def stage_moves(spec: dict, runs: list):
    """Actual displacement (px) of the print in the image for each run, with its parts."""
    st = spec["stage"]
    scale = float(spec["scale_px_per_mm"])
    T = float(st["travel_scale"])
    Rm = rot(float(st["misalign_rad"]))
    const = np.array([float(v) for v in st["constant_offset_px"]])
    sig_px = float(st["repeatability_um"]) * scale / 1000.0
    for r in runs:
        cmd = np.array(r["commanded_mm"])
        moved = bool(np.any(cmd != 0))
        travel = scale * T * (Rm @ cmd)
        c = const if moved else np.zeros(2)
        if moved and sig_px > 0:
            rng = np.random.default_rng(_seed_seq(int(spec["seed"]), 3, r["id"]))
            rnd = rng.normal(0.0, sig_px, 2)
        else:
            rnd = np.zeros(2)
        expl = np.array([float(v) for v in st["per_run_offsets_px"].get(r["id"], [0.0, 0.0])])
        d = travel + c + rnd + expl
        M = (1.0 + r["scale_ds"]) * rot(r["rotation_rad"])
        r["travel_px"] = travel.tolist()
        r["offset_px"] = {"constant": c.tolist(), "random": rnd.tolist(), "explicit": expl.tolist(),
                          "total": (c + rnd + expl).tolist()}
        r["actual_move_px"] = d.tolist()
        r["actual_move_mm"] = (d / scale).tolist()
        r["M"] = M
        r["image_map_undistorted"] = {
            "A": (M - np.eye(2)).tolist(),
            "b": (M @ d).tolist(),
            "note": "u_def = M (u_ref + d), so u_def - u_ref = A u_ref + b with A = M - I, b = M d; "
                    "u are undistorted offsets (px) from the optical axis; M = (1+scale_ds) R(rotation_rad)",
        }
        r["displacement_at_axis_px"] = (M @ d).tolist()


def _field_bounds(cam: Camera, frames, margin_px):
    """Print region (mm) seen by any frame, plus a margin."""
    W, H = cam.W, cam.H
    n = 200
    xs = np.linspace(-0.5, W - 0.5, n)
    ys = np.linspace(-0.5, H - 0.5, n)
    border = np.concatenate([
        np.stack([xs, np.full(n, -0.5)], 1), np.stack([xs, np.full(n, H - 0.5)], 1),
        np.stack([np.full(n, -0.5), ys], 1), np.stack([np.full(n, W - 0.5), ys], 1)])
    ud = border - cam.axis
    uu = cam.undistort(ud)
    lo = np.array([np.inf, np.inf])
    hi = -lo
    for fr in frames:
        if cam.perspective_on:
            P = fr.undistorted_to_print(cam.unproject(uu, fr), cam.scale)
        else:
            P = fr.undistorted_to_print(uu, cam.scale)
        lo = np.minimum(lo, P.min(axis=0))
        hi = np.maximum(hi, P.max(axis=0))
    m = margin_px / cam.scale
    return lo[0] - m, hi[0] + m, lo[1] - m, hi[1] + m, (lo[0], hi[0], lo[1], hi[1])


def _perspective_mag_max(cam: Camera, frames) -> float:
    """Largest local linear magnification of the tilt/bow (sqrt det J) at the frame border, ≥ 1."""
    if not cam.perspective_on:
        return 1.0
    W, H = cam.W, cam.H
    n = 50
    xs = np.linspace(-0.5, W - 0.5, n)
    ys = np.linspace(-0.5, H - 0.5, n)
    border = np.concatenate([
        np.stack([xs, np.full(n, -0.5)], 1), np.stack([xs, np.full(n, H - 0.5)], 1),
        np.stack([np.full(n, -0.5), ys], 1), np.stack([np.full(n, W - 0.5), ys], 1)])
    uu = cam.undistort(border - cam.axis)
    best = 1.0
    for fr in frames:
        u = cam.unproject(uu, fr)
        Minv = np.linalg.inv(fr.M)
        P = fr.undistorted_to_print(u, cam.scale)
        _, _, J = cam.perspective(u / cam.scale, P, Minv)
        det = J[:, 0, 0] * J[:, 1, 1] - J[:, 0, 1] * J[:, 1, 0]
        best = max(best, float(np.sqrt(np.maximum(det, 0.0)).max()))
    return best


# --------------------------------------------------------------------------------------------
# Dataset
# --------------------------------------------------------------------------------------------


def _pattern_manifest(spec, pr: Print, cam: Camera):
    sp = spec["state_print"]
    out = {"label": pr.label}
    if sp in ("nominal", "characterised"):
        out["dot_diameter_mm"] = pr.d_nom
        out["dot_spacing_mm"] = pr.s_nom
    if sp == "characterised":
        out["profile"] = pr.profile
        out["contrast"] = pr.c
        out["edge_softness_mm"] = pr.soft
        f = np.linspace(0.0, 0.5 * cam.scale, 15)
        t = pr.transfer(f)
        out["mtf"] = [[float(a), float(abs(b))] for a, b in zip(f, t)]
    return out


def _prepare_out_dir(out_dir: Path, overwrite: bool):
    if out_dir.exists():
        if not out_dir.is_dir():
            raise FileExistsError(f"{out_dir} exists and is not a folder")
        if any(out_dir.iterdir()):
            if not overwrite:
                raise FileExistsError(f"{out_dir} is not empty (set \"overwrite\": true or pass --overwrite)")
            for f in out_dir.iterdir():
                if f.is_file() and (f.suffix.lower() in (".tif", ".tiff") or f.name in ("dataset.json", "truth.json")):
                    f.unlink()
            if (out_dir / "truth_dots").is_dir():
                shutil.rmtree(out_dir / "truth_dots")
    out_dir.mkdir(parents=True, exist_ok=True)


def _noise_prediction(spec):
    g = spec["gain_e_per_dn"]
    return {
        "model": "DN = round(clip(Poisson(white_level_dn*E*gain_e_per_dn)/gain_e_per_dn + N(0, read_noise_dn^2) + dark_offset_dn))",
        "variance_dn2": "S/gain_e_per_dn + read_noise_dn^2 + 1/12 (quantisation), S = white_level_dn*E the mean signal (DN)",
        "variance_at_white_dn2": (float(spec["white_level_dn"]) / float(g) if g else 0.0)
        + float(spec["read_noise_dn"]) ** 2 + 1.0 / 12.0,
    }


def _frames_of(lab: str, pruns: list):
    """The reference frame of pattern `lab` and the deformed frames of its runs."""
    ref = Frame(f"{lab}_ref.tif", "reference", np.eye(2), np.zeros(2), 1.0, 0.0)
    dframes = [Frame(r["deformed"], "deformed", r["M"], np.array(r["actual_move_px"]),
                     r["illumination_gain"], r["scale_ds"]) for r in pruns]
    return ref, dframes


def _travel_frames(spec: dict, runs: list) -> list:
    """Frames at the corners of spec["frame_travel_mm"] ([x0, x1, y0, y1], optional): the print then
    covers every position a single-frame call (`--frame`) may ask for, the same print each time."""
    travel = spec.get("frame_travel_mm")
    if not travel:
        return []
    x0, x1, y0, y1 = (float(v) for v in travel)
    corners = []
    for k, (x, y) in enumerate(((x0, y0), (x1, y0), (x0, y1), (x1, y1))):
        r = _ad_hoc_run(spec, runs, f"travel-corner-{k}", x, y)
        corners.append(Frame(f"corner{k}", "deformed", r["M"], np.array(r["actual_move_px"]),
                             r["illumination_gain"], r["scale_ds"]))
    return corners


def _ad_hoc_run(spec: dict, runs: list, run_id: str, x_mm: float, y_mm: float) -> dict:
    """A run at a commanded position the spec's moves do not name (its effects the spec's own)."""
    eff = spec["effects"]
    r = {"id": run_id, "commanded_mm": [x_mm, y_mm]}
    for key in _PER_MOVE_OVERRIDES:
        r[key] = float(eff[key])
    stage_moves(spec, [r])
    return r


def _print_for(spec: dict, cam: "Camera", pat: dict, ref: "Frame", dframes: list):
    """The print of pattern `pat`, laid out over what the frames see (plus a margin for the dots'
    reach), and the inner bounds its statistics are taken over."""
    render = spec["render"]
    # margin: the widest dot reach in px, generous for magnification and distortion
    dmax = float(pat["dot_diameter_mm"]) * (1 + 3 * float(pat["diameter_cv"]))
    lin_max = cam.scale * max([1.0] + [f.lin for f in dframes]) * 1.1
    if cam.perspective_on:
        lin_max *= _perspective_mag_max(cam, [ref] + dframes)
    sig_px = lin_max * math.hypot(dmax / FWHM_PER_SIGMA, float(pat["edge_softness_mm"]))
    sig_px = math.hypot(sig_px, cam.psf)
    margin = float(render["window_sigmas"]) * sig_px + 0.5 * dmax * lin_max + 4
    x0, x1, y0, y1, inner = _field_bounds(cam, [ref] + dframes, margin)
    return Print(pat, int(spec["seed"]), (x0, x1, y0, y1), render), inner


def single_frame(user_spec: dict, x_mm: float, y_mm: float, target: str, index: int, out: Path) -> str:
    """One frame, as a camera on the spec's bench delivers it with the stage at (x_mm, y_mm), the
    pattern `target` mounted (the first pattern when empty) and `index` frames taken since the
    mount: what `generate` writes for the same frame, bit for bit, where the dataset has one (the
    first frame at the origin is the reference, later ones its repeats; a run's commanded position
    gives that run's deformed frame, the same noise on every visit), and otherwise a frame at an
    ad-hoc position with noise of its own. Returns the file name the frame has in a dataset."""
    spec = effective_spec(user_spec)
    cam = Camera(spec)
    runs = plan_runs(spec)
    stage_moves(spec, runs)
    labels = [p["label"] for p in spec["patterns"]]
    lab = target or labels[0]
    if lab not in labels:
        raise SpecError(f"target '{lab}' is not a pattern of the spec ({', '.join(labels)})")
    pat = spec["patterns"][labels.index(lab)]
    pruns = [r for r in runs if r["pattern"] == lab]
    ref, dframes = _frames_of(lab, pruns)
    pr, _ = _print_for(spec, cam, pat, ref, dframes + _travel_frames(spec, runs))
    if x_mm == 0.0 and y_mm == 0.0:
        fr, name = ref, (ref.name if index == 0 else f"{lab}_ref_r{index}.tif")
    else:
        named = [(r, f) for r, f in zip(pruns, dframes) if r["commanded_mm"] == [x_mm, y_mm]]
        if named:
            fr, name = named[0][1], named[0][1].name
        else:
            name = f"{lab}_at_{x_mm!r}_{y_mm!r}_f{index}.tif"
            r = _ad_hoc_run(spec, runs, f"{lab}-at-{x_mm!r}-{y_mm!r}", x_mm, y_mm)
            fr = Frame(name, "deformed", r["M"], np.array(r["actual_move_px"]),
                       r["illumination_gain"], r["scale_ds"])
    irr, _ = render_irradiance(cam, pr, fr, spec["render"])
    img, _ = expose(irr, spec, np.random.default_rng(_seed_seq(int(spec["seed"]), 2, name)))
    write_tiff(Path(out), img)
    return name


def generate(spec: dict, out_dir, overwrite: bool | None = None, quiet: bool = True) -> dict:
    """Write the dataset (dataset.json, TIFFs, truth.json) into out_dir; return the truth dict."""
    t_start = time.perf_counter()
    spec = effective_spec(spec)
    out_dir = Path(out_dir)
    cam = Camera(spec)
    render = spec["render"]
    runs = plan_runs(spec)
    if not runs:
        raise SpecError("no runs: give at least one move or step series")
    stage_moves(spec, runs)
    _prepare_out_dir(out_dir, bool(spec["overwrite"]) if overwrite is None else overwrite)
    seed = int(spec["seed"])

    def log(msg):
        if not quiet:
            print(msg, file=sys.stderr, flush=True)

    truth_patterns, frames_truth = [], {}
    manifest_runs = []
    for pat in spec["patterns"]:
        lab = pat["label"]
        pruns = [r for r in runs if r["pattern"] == lab]
        ref, dframes = _frames_of(lab, pruns)
        t0 = time.perf_counter()
        pr, inner = _print_for(spec, cam, pat, ref, dframes + _travel_frames(spec, runs))
        t_print = time.perf_counter() - t0
        log(f"[{lab}] print: {pr.x.size} dots in {t_print:.2f} s")
        st = pr.stats(inner, cam.scale)
        f = np.linspace(0.0, 0.5 * cam.scale, 15)
        tr = pr.transfer(f)
        pt = {"label": lab, "spec": pat, "seed": {"spec_seed": seed if "seed" not in pat else int(pat["seed"]),
                                                   "sub_seed": "SeedSequence(entropy=seed, spawn_key=(1, crc32(label)))"},
              "profile": pr.profile, "contrast": pr.c, "dot_diameter_mm_nominal": pr.d_nom,
              "dot_spacing_mm_nominal": pr.s_nom, "edge_softness_mm": pr.soft,
              "sigma_mm": (float(math.hypot(pr.d_nom / FWHM_PER_SIGMA, pr.soft)) if pr.profile == "gaussian" else None),
              "statistics": st, "print_seconds": round(t_print, 3),
              "transfer_function": [[float(a), float(b)] for a, b in zip(f, tr)]}
        if render.get("write_dot_lists", True):
            (out_dir / "truth_dots").mkdir(exist_ok=True)
            np.save(out_dir / "truth_dots" / f"{lab}.npy", np.stack([pr.x, pr.y, pr.d], axis=1))
            pt["dot_list"] = f"truth_dots/{lab}.npy (columns x_mm, y_mm, diameter_mm; print coordinates)"
        truth_patterns.append(pt)

        # reference and its static repeats share one irradiance, independent noise
        irr, diag = render_irradiance(cam, pr, ref, render)
        log(f"[{lab}] reference rendered in {diag['render_seconds']:.2f} s ({diag['dots_rendered']} dots)")
        ref_files = [ref.name] + [f"{lab}_ref_r{k}.tif" for k in range(1, spec["repeats"] + 1)]
        for fname in ref_files:
            rng = np.random.default_rng(_seed_seq(seed, 2, fname))
            img, qd = expose(irr, spec, rng)
            write_tiff(out_dir / fname, img)
            frames_truth[fname] = {"kind": "reference" if fname == ref.name else "repeat", "pattern": lab,
                                   "noise_seed": f"SeedSequence(entropy={seed}, spawn_key=(2, crc32('{fname}')))",
                                   **diag, **qd}
        for ro in spec["hardware_readouts"]:
            fname = _readout_file(ro, ref.name)
            write_tiff(out_dir / fname, read_out(irr, spec, np.random.default_rng(_seed_seq(seed, 4, fname)), ro))
            frames_truth[fname] = {"kind": "reference", "pattern": lab, "read_out": ro["name"]}
        del irr
        pm = _pattern_manifest(spec, pr, cam)
        for r, fr in zip(pruns, dframes):
            irr, diag = render_irradiance(cam, pr, fr, render)
            rng = np.random.default_rng(_seed_seq(seed, 2, fr.name))
            img, qd = expose(irr, spec, rng)
            write_tiff(out_dir / fr.name, img)
            frames_truth[fr.name] = {"kind": "deformed", "pattern": lab, "run": r["id"],
                                     "noise_seed": f"SeedSequence(entropy={seed}, spawn_key=(2, crc32('{fr.name}')))",
                                     **diag, **qd}
            log(f"[{lab}] {fr.name} rendered in {diag['render_seconds']:.2f} s")
            run = {"id": r["id"], "pattern": dict(pm), "reference": r["reference"], "deformed": r["deformed"],
                   "stage": {"dx_mm": r["commanded_mm"][0], "dy_mm": r["commanded_mm"][1]}}
            if spec["repeats"] > 0:
                run["repeat"] = ref_files[1:]
            manifest_runs.append(run)
            # The same irradiance read out in each of the camera's own modes: a run per mode,
            # after its full-resolution twin.
            for ro in spec["hardware_readouts"]:
                fname = _readout_file(ro, fr.name)
                write_tiff(out_dir / fname,
                           read_out(irr, spec, np.random.default_rng(_seed_seq(seed, 4, fname)), ro))
                frames_truth[fname] = {"kind": "deformed", "pattern": lab, "run": r["id"], "read_out": ro["name"]}
                manifest_runs.append({
                    "id": f"{r['id']}_{_readout_stem(ro)}", "pattern": dict(pm),
                    "reference": _readout_file(ro, r["reference"]), "deformed": fname,
                    "stage": dict(run["stage"]), "capture": capture_mode(ro), "twin_of": r["id"]})

    manifest = {
        "format": "ffdic-dataset/1",
        "name": spec["name"],
        "scale_px_per_mm": cam.scale,
        "camera": {"width": cam.W, "height": cam.H, "bit_depth": spec["bit_depth"]},
    }
    if spec.get("stated_repeatability_um") is not None:
        manifest["stage_repeatability_um"] = float(spec["stated_repeatability_um"])
    if opt_top(spec, "state_working_distance"):
        manifest["working_distance_mm"] = cam.Z
    manifest["generator"] = {"name": GENERATOR_NAME, "spec": spec}
    manifest["runs"] = manifest_runs
    with open(out_dir / "dataset.json", "w") as fh:
        json.dump(manifest, fh, indent=2)
        fh.write("\n")

    truth_runs = []
    for r in runs:
        q = {k: v for k, v in r.items() if k != "M"}
        q["M"] = r["M"].tolist()
        q["stage_model"] = ("d = scale*travel_scale*R(misalign_rad)*commanded_mm + offset; offset = constant "
                            "(moved runs only) + N(0, repeatability_um*scale/1000) per axis (moved runs only) "
                            "+ per_run_offsets_px (always)")
        truth_runs.append(q)
    eff = spec["effects"]
    truth = {
        "format": TRUTH_FORMAT,
        "generator": GENERATOR_NAME,
        "name": spec["name"],
        "spec": spec,
        "conventions": {
            "coordinates": "x = column index (right), y = row index (down)",
            "pixel_centre": "pixel (column i, row j) is centred at (x, y) = (i, j) and spans [i-0.5, i+0.5) x [j-0.5, j+0.5)",
            "optical_axis_px": cam.axis.tolist(),
            "r0_half_diagonal_px": cam.r0,
            "rotation_sign": "positive angle turns +x toward +y (clockwise on screen, y down); R = [[cos,-sin],[sin,cos]]",
            "print_to_image": "u = M (scale*P_mm + d_px) (in-plane offset from the axis, px; M = I, d = 0 for the "
                              "reference); q = u/scale (mm); W = Ry(tilt_about_y_rad) Rx(tilt_about_x_rad) (qx, qy, 0) "
                              "+ (0, 0, Z + target_bow_per_mm |P_mm|^2/2); u' = scale Z (Wx/Wz, Wy/Wz) (undistorted "
                              "offset, px; u' = u without tilt and bow); x = axis + u' + r0 (dxn, dyn) (Brown-Conrady "
                              "about e = axis + distortion_centre_px, qn = (axis + u' - e)/r0; for k1 alone about "
                              "the axis: x = axis + u' (1 + k1_per_px2 |u'|^2))",
            "tilt_rotations": "Rx(t) = [[1,0,0],[0,cos t,-sin t],[0,sin t,cos t]] (+y side of the target farther "
                              "for t > 0); Ry(t) = [[cos t,0,-sin t],[0,1,0],[sin t,0,cos t]] (+x side farther "
                              "for t > 0); camera frame x right, y down, z along the view",
            "print_origin": "print coordinate (0, 0) mm images onto the optical axis in the reference frame",
            "hardware_read_out": "per axis a block of binning*decimation sensor pixels per output pixel; the "
                                 "first `binning` pixels of the block binned (decimation keeps the first pixel); "
                                 "digital: each pixel exposed and digitised, then averaged/summed and rounded; "
                                 "charge: electrons summed, one shot and read noise draw, /n for an average",
        },
        "camera": {"width": cam.W, "height": cam.H, "bit_depth": spec["bit_depth"], "scale_px_per_mm": cam.scale},
        "effects": {
            "rotation_rad": float(eff["rotation_rad"]), "scale_ds": float(eff["scale_ds"]),
            "k1_per_px2": cam.k1, "k1_norm": cam.k1 * cam.r0 ** 2, "r0_px": cam.r0,
            "psf_sigma_px": cam.psf, "vignetting_v": cam.vig, "fill_factor": [cam.fx, cam.fy],
            "illumination_gain": float(eff["illumination_gain"]),
            "vignetting_model": "E *= 1 - v r^2 / r0^2, r from the axis at the pixel centre, r0 = half diagonal",
            "k2_norm": cam.k2n, "k2_per_px4": cam.k2n / cam.r0 ** 4,
            "p1_norm": cam.p1n, "p2_norm": cam.p2n,
            "p1_per_px": cam.p1n / cam.r0, "p2_per_px": cam.p2n / cam.r0,
            "distortion_centre_px": cam.dcentre.tolist(),
            "distortion_centre_abs_px": (cam.axis + cam.dcentre).tolist(),
            "distortion_model": "Brown-Conrady on absolute image positions x (px): e = axis + distortion_centre_px, "
                                "qn = (x - e)/r0, r^2 = |qn|^2, radial = k1_norm r^2 + k2_norm r^4, "
                                "dxn = qn_x radial + 2 p1 qn_x qn_y + p2 (r^2 + 2 qn_x^2), "
                                "dyn = qn_y radial + p1 (r^2 + 2 qn_y^2) + 2 p2 qn_x qn_y, x_d = x + r0 (dxn, dyn). "
                                "Per px (v = x - e in px): dx = v_x (k1_per_px2 |v|^2 + k2_per_px4 |v|^4) "
                                "+ 2 p1_per_px v_x v_y + p2_per_px (|v|^2 + 2 v_x^2), likewise dy",
            "tilt_about_y_rad": cam.theta_y, "tilt_about_x_rad": cam.theta_x,
            "working_distance_mm": cam.Z,
            "tilt_a_per_px": cam.tilt_first_order()[0], "tilt_b_per_px": cam.tilt_first_order()[1],
            "tilt_model": "pinhole: W = Ry(tilt_about_y_rad) Rx(tilt_about_x_rad) (q, 0) + (0, 0, Z), "
                          "u' = scale Z (Wx, Wy)/Wz; to first order, a translation t (px) of the target in its "
                          "plane changes the displacement at image offset p (px from the axis) by "
                          "-a (2 px tx + tx^2, px ty + py tx + tx ty) - b (px ty + py tx + tx ty, 2 py ty + ty^2), "
                          "a = tan(tilt_about_y_rad)/(Z scale), b = tan(tilt_about_x_rad)/(Z scale) (1/px)",
            "target_bow_per_mm": cam.bow,
            "bow_model": "depth offset z(P) = target_bow_per_mm |P|^2/2 (mm) along the camera's z, P the print "
                         "coordinate (moves with the print; apex at print (0, 0)); W = Ry Rx (q, 0) + (0, 0, Z + z(P)). "
                         "Not in ffdic's catalogue on purpose",
            "lamp_ramp_per_px": [float(v) for v in cam.ramp],
            "lamp_model": "moved (deformed) frames only: irradiance x (1 + ax x + ay y), x, y px from the axis "
                          "(pixel centres); not in ffdic's catalogue on purpose",
            "dot_shape_under_tilt_and_distortion": "each dot rendered isotropic with the local areal magnification "
                                                   "sqrt(det J) of the tilt/bow and of the distortion (approximation)",
        },
        "noise": _noise_prediction(spec),
        "stated_repeatability_um": spec.get("stated_repeatability_um"),
        "patterns": truth_patterns,
        "runs": truth_runs,
        "frames": frames_truth,
        "total_seconds": round(time.perf_counter() - t_start, 3),
    }
    if cam.saddle != 0:
        # written only when used: a spec without it keeps its truth.json byte for byte
        truth["effects"]["target_saddle_per_mm"] = cam.saddle
        truth["effects"]["saddle_model"] = (
            "depth offset z(P) = target_saddle_per_mm (P_x^2 - P_y^2)/2 (mm), added to the bow's and moving "
            "with the print as it does. Not in ffdic's catalogue on purpose")
    with open(out_dir / "truth.json", "w") as fh:
        json.dump(truth, fh, indent=2)
        fh.write("\n")
    log(f"done in {truth['total_seconds']:.2f} s -> {out_dir}")
    return truth


def main(argv=None):
    ap = argparse.ArgumentParser(description="Independent synthetic speckle dataset generator for ffdic")
    ap.add_argument("spec", help="spec JSON file")
    ap.add_argument("out_dir", nargs="?", help="output dataset folder (must be empty or absent)")
    ap.add_argument("--overwrite", action="store_true", help="replace an existing dataset in OUT_DIR")
    ap.add_argument("--quiet", action="store_true")
    ap.add_argument("--frame", action="store_true",
                    help="one frame, as a camera delivers it: the stage position, target, frame index and "
                         "output path from FFDIC_X_MM, FFDIC_Y_MM, FFDIC_TARGET, FFDIC_FRAME, FFDIC_OUT "
                         "(what ffdic's exec camera sets)")
    a = ap.parse_args(argv)
    with open(a.spec) as fh:
        spec = json.load(fh)
    try:
        if a.frame:
            env = os.environ
            single_frame(spec, float(env.get("FFDIC_X_MM", "0")), float(env.get("FFDIC_Y_MM", "0")),
                         env.get("FFDIC_TARGET", ""), int(env.get("FFDIC_FRAME", "0")), Path(env["FFDIC_OUT"]))
            return 0
        if not a.out_dir:
            ap.error("OUT_DIR is needed without --frame")
        generate(spec, a.out_dir, overwrite=True if a.overwrite else None, quiet=a.quiet)
    except (SpecError, FileExistsError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
