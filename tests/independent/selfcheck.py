#!/usr/bin/env python3
"""Independent sanity checks of generate.py (and sample3_dataset.py).

    python selfcheck.py [--keep DIR]

Exit code 0 when every check passes, 1 otherwise. Every measurement here is our own numpy code
(FFT phase correlation + Gauss-Newton sub-pixel refinement on a mirror-padded Fourier shift),
never ffdic's. Runs in well under a minute on one core.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse
import hashlib
import json
import math
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import tifffile

HERE = Path(__file__).resolve().parent
sys.dont_write_bytecode = True  # leave no __pycache__ in the repository
sys.path.insert(0, str(HERE))
import generate as G  # noqa: E402

RESULTS = []


def check(name, ok, detail):
    RESULTS.append((name, bool(ok), detail))
    print(f"[{'PASS' if ok else 'FAIL'}] {name}: {detail}", flush=True)


# --------------------------------------------------------------------------------------------
# Shift measurement (own code)
# --------------------------------------------------------------------------------------------


def _hann(n):
    return 0.5 - 0.5 * np.cos(2 * np.pi * (np.arange(n) + 0.5) / n)


def phase_corr_integer(a, b):
    """Integer shift d with b(x) ≈ a(x − d), by phase correlation of Hann-windowed images."""
    H, W = a.shape
    w = _hann(H)[:, None] * _hann(W)[None, :]
    Fa = np.fft.fft2((a - a.mean()) * w)
    Fb = np.fft.fft2((b - b.mean()) * w)
    R = Fb * np.conj(Fa)
    R /= np.abs(R) + 1e-12
    c = np.fft.ifft2(R).real
    iy, ix = np.unravel_index(np.argmax(c), c.shape)
    if iy > H // 2:
        iy -= H
    if ix > W // 2:
        ix -= W
    return int(ix), int(iy)


def fourier_shift(img, dx, dy):
    """img(x + dx, y + dy) and its gradient, by the shift theorem on the mirror-padded image."""
    H, W = img.shape
    p = np.pad(img, ((0, H), (0, W)), mode="symmetric")
    F = np.fft.fft2(p)
    ky = 2 * np.pi * np.fft.fftfreq(2 * H)[:, None]
    kx = 2 * np.pi * np.fft.fftfreq(2 * W)[None, :]
    F = F * np.exp(1j * (kx * dx + ky * dy))
    s = np.fft.ifft2(F).real[:H, :W]
    gx = np.fft.ifft2(F * (1j * kx)).real[:H, :W]
    gy = np.fft.ifft2(F * (1j * ky)).real[:H, :W]
    return s, gx, gy


def refine_shift(ref, mov, margin=12, iters=10):
    """Sub-pixel d (|d| < ~1.5 px) with mov(x) ≈ ref(x − d): Gauss-Newton on mov(x + d) − ref(x)."""
    d = np.zeros(2)
    roi = (slice(margin, ref.shape[0] - margin), slice(margin, ref.shape[1] - margin))
    r0 = ref[roi]
    for _ in range(iters):
        s, gx, gy = fourier_shift(mov, d[0], d[1])
        r = (s[roi] - r0).ravel()
        J = np.stack([gx[roi].ravel(), gy[roi].ravel()], axis=1)
        step = -np.linalg.solve(J.T @ J, J.T @ r)
        d += step
        if np.abs(step).max() < 1e-6:
            break
    return d


def measure_global_shift(ref, mov, margin=12):
    """Shift d (px) of the content from ref to mov (mov(x) ≈ ref(x − d)), over their overlap."""
    ref = ref.astype(float)
    mov = mov.astype(float)
    ix, iy = phase_corr_integer(ref, mov)
    H, W = ref.shape
    xa, xb = max(0, -ix), W - max(0, ix)
    ya, yb = max(0, -iy), H - max(0, iy)
    rc = ref[ya:yb, xa:xb]
    mc = mov[ya + iy:yb + iy, xa + ix:xb + ix]
    return np.array([ix, iy]) + refine_shift(rc, mc, margin)


def measure_local_shift(ref, mov, cx, cy, field, half=48, margin=12):
    """Translation of the subset centred at (cx, cy) in ref, and what a translation-only least-squares
    fit must return for the model displacement field `field(x, y) -> (ux, uy)` (ref pixel coords):
    linearised, d = (Σ g gᵀ)⁻¹ Σ g gᵀ u(x) over the fit's region, g = ∇ref. For a uniform field
    this is u; for a varying field it is the gradient-weighted mean, not u at the centre."""
    ref = ref.astype(float)
    mov = mov.astype(float)
    guess = np.array(field(np.array([cx]), np.array([cy]))).ravel()
    gx, gy = int(round(guess[0])), int(round(guess[1]))
    x0, y0 = int(round(cx)) - half, int(round(cy)) - half
    rc = ref[y0:y0 + 2 * half, x0:x0 + 2 * half]
    mc = mov[y0 + gy:y0 + gy + 2 * half, x0 + gx:x0 + gx + 2 * half]
    meas = np.array([gx, gy]) + refine_shift(rc, mc, margin)
    _, grx, gry = fourier_shift(rc, 0.0, 0.0)
    roi = (slice(margin, 2 * half - margin), slice(margin, 2 * half - margin))
    ys, xs = np.mgrid[y0:y0 + 2 * half, x0:x0 + 2 * half]
    ux, uy = field(xs[roi].ravel().astype(float), ys[roi].ravel().astype(float))
    g = np.stack([grx[roi].ravel(), gry[roi].ravel()], axis=1)
    u = np.stack([ux, uy], axis=1)
    expected = np.linalg.solve(g.T @ g, g.T @ (g * u).sum(axis=1))
    return meas, expected


def read(d, name):
    return tifffile.imread(Path(d) / name)


# --------------------------------------------------------------------------------------------
# Checks
# --------------------------------------------------------------------------------------------


def check_special_functions():
    rng = np.random.default_rng(5)
    t = np.concatenate([rng.uniform(-9, 9, 20000), np.linspace(-8.6, 8.6, 1001)])
    exact = np.array([0.5 * math.erfc(-v / math.sqrt(2)) for v in t])
    err = np.abs(G.norm_cdf(t) - exact).max()
    check("Phi table vs math.erfc", err < 5e-9, f"max |error| = {err:.2e} (limit 5e-9)")
    ex_psi = t * exact + np.exp(-0.5 * t * t) / math.sqrt(2 * math.pi)
    err = np.abs(G.psi1(t) - ex_psi).max()
    check("Psi1 table vs t*Phi+phi", err < 1e-8, f"max |error| = {err:.2e} (limit 1e-8)")
    known = {1.0: 0.44005058574493355, 5.0: -0.3275791375914652, 10.0: 0.04347274616886144,
             3.8317059702075125: 0.0}
    err = max(abs(float(G.bessel_j1(np.array([k]))[0]) - v) for k, v in known.items())
    check("Bessel J1 (quadrature) vs reference values", err < 1e-12, f"max |error| = {err:.1e}")


def check_disk_area():
    rng = np.random.default_rng(11)
    worst = 0.0
    n_mc = 2_000_000
    for _ in range(12):
        R = rng.uniform(0.3, 3.0)
        cx, cy = rng.uniform(-1, 1, 2)
        x0, y0 = rng.uniform(-R - 1, R, 2)
        x1, y1 = x0 + rng.uniform(0.2, 2 * R + 1), y0 + rng.uniform(0.2, 2 * R + 1)
        a = float(G.disk_rect_area(cx, cy, R, x0, x1, y0, y1))
        px = rng.uniform(x0, x1, n_mc)
        py = rng.uniform(y0, y1, n_mc)
        frac = ((px - cx) ** 2 + (py - cy) ** 2 <= R * R).mean()
        mc = frac * (x1 - x0) * (y1 - y0)
        se = math.sqrt(max(frac * (1 - frac), 1e-12) / n_mc) * (x1 - x0) * (y1 - y0)
        worst = max(worst, abs(a - mc) / max(se, 1e-9))
    full = float(G.disk_rect_area(0.3, -0.2, 1.7, -5, 5, -5, 5)) / (math.pi * 1.7 ** 2) - 1
    check("exact disk∩rectangle area vs Monte Carlo (2e6 points, 12 cases)",
          worst < 5 and abs(full) < 1e-13, f"worst deviation {worst:.2f} σ_MC; full disk rel. error {full:.1e}")


def _single_dot(profile, psf, fill, cx=20.3, cy=19.6, soft=0.0):
    spec = G.effective_spec({"width": 41, "height": 40, "scale_px_per_mm": 10.0,
                             "patterns": [{"label": "a", "profile": profile, "dot_diameter_mm": 0.5,
                                           "dot_spacing_mm": 2.0, "contrast": 0.6, "edge_softness_mm": soft}],
                             "effects": {"psf_sigma_px": psf, "fill_factor": fill}})
    cam = G.Camera(spec)
    pr = G.Print(spec["patterns"][0], 1, (-1, 1, -1, 1), spec["render"])
    pr.x = np.array([(cx - cam.axis[0]) / cam.scale])
    pr.y = np.array([(cy - cam.axis[1]) / cam.scale])
    pr.d = np.array([0.5])
    fr = G.Frame("t", "reference", np.eye(2), np.zeros(2), 1.0, 0.0)
    irr, diag = G.render_irradiance(cam, pr, fr, spec["render"])
    return 1.0 - irr, diag


def check_pixel_centre():
    """A dot at print (X, Y) mm images at axis + scale·(X, Y); the axis is ((W−1)/2, (H−1)/2) and
    pixel (i, j) is centred at (i, j): the deficit's centroid over pixel centres shows both."""
    W, H = 64, 51
    spec = G.effective_spec({"width": W, "height": H, "scale_px_per_mm": 10.0,
                             "patterns": [{"label": "a", "profile": "gaussian", "dot_diameter_mm": 0.5,
                                           "dot_spacing_mm": 2.0, "contrast": 0.6}],
                             "effects": {"fill_factor": [0.5, 0.3]}})
    cam = G.Camera(spec)
    worst = 0.0
    for X, Y in ((0.0, 0.0), (0.83, -0.61)):
        pr = G.Print(spec["patterns"][0], 1, (-1, 1, -1, 1), spec["render"])
        pr.x, pr.y, pr.d = np.array([X]), np.array([Y]), np.array([0.5])
        fr = G.Frame("t", "reference", np.eye(2), np.zeros(2), 1.0, 0.0)
        irr, _ = G.render_irradiance(cam, pr, fr, spec["render"])
        dfc = 1 - irr
        ys, xs = np.mgrid[0:H, 0:W]
        c = np.array([(dfc * xs).sum(), (dfc * ys).sum()]) / dfc.sum()
        want = np.array([(W - 1) / 2 + 10 * X, (H - 1) / 2 + 10 * Y])
        worst = max(worst, np.abs(c - want).max())
    check("pixel centres at integer coordinates, axis at ((W−1)/2, (H−1)/2)", worst < 1e-6,
          f"centroid of a dot at print (0, 0) and (0.83, −0.61) mm vs axis + scale·P: max error {worst:.1e} px")


def check_single_dots():
    # Gaussian: ∫ deficit = c 2π σ² (σ in px) for any PSF / fill factor; exact erf integration
    s_px = 5.0 / G.FWHM_PER_SIGMA
    vol_g = 0.6 * 2 * math.pi * s_px ** 2
    worst = 0.0
    for psf, fill in ((0.0, [1, 1]), (0.8, [0.5, 0.7])):
        dfc, _ = _single_dot("gaussian", psf, fill)
        worst = max(worst, abs(dfc.sum() / vol_g - 1))
    # and pointwise against direct numerical integration over the aperture (fill 0.5 x 0.7, psf 0.8)
    dfc, _ = _single_dot("gaussian", 0.8, [0.5, 0.7])
    st = math.hypot(s_px, 0.8)
    amp = vol_g / (2 * math.pi * st ** 2)
    j, i = 22, 18
    u = (np.arange(200) + 0.5) / 200 - 0.5
    xs = i + 0.5 * u
    ys = j + 0.7 * u
    ref = amp * np.exp(-((xs[None, :] - 20.3) ** 2 + (ys[:, None] - 19.6) ** 2) / (2 * st ** 2)).mean()
    perr = abs(dfc[j, i] - ref)
    check("Gaussian dot: volume conserved and aperture integral exact", worst < 1e-6 and perr < 1e-6,
          f"volume rel. error {worst:.1e}, pixel vs midpoint quadrature {perr:.1e}")
    # hard disk, exact area
    R = 2.5
    vol_d = 0.6 * math.pi * R * R
    dfc, diag = _single_dot("disk", 0.0, [1, 1])
    e1 = abs(dfc.sum() / vol_d - 1)
    a = float(G.disk_rect_area(20.3, 19.6, R, 20.5, 21.5, 17.5, 18.5)) * 0.6
    e2 = abs(dfc[18, 21] - a)
    dfc2, _ = _single_dot("disk", 0.0, [0.6, 0.8])
    a2 = float(G.disk_rect_area(20.3, 19.6, R, 21 - 0.3, 21 + 0.3, 18 - 0.4, 18 + 0.4)) * 0.6 / 0.48
    e3 = abs(dfc2[18, 21] - a2)
    check("hard disk: exact area rendering (fill 1 and 0.6x0.8)", e1 < 1e-12 and e2 < 1e-12 and e3 < 1e-12,
          f"volume rel. error {e1:.1e}, pixel errors {e2:.1e}, {e3:.1e} ({diag['render_method']})")
    # blurred disk (strips) against a brute-force 32x supersampled exact-area + sampled-Gaussian render
    psf = 0.6
    ss = 32
    n = 41 * ss
    h = 1.0 / ss
    e = np.arange(n + 1) * h - 0.5
    Gc = G.disk_corner_area(e[None, :] - 20.3, e[:, None] - 19.6, R)
    fine = (Gc[1:, 1:] - Gc[1:, :-1] - Gc[:-1, 1:] + Gc[:-1, :-1]) / (h * h) * 0.6  # (n, n) rows=y
    k = np.arange(-int(5 * psf * ss), int(5 * psf * ss) + 1) * h
    g = np.exp(-k * k / (2 * psf * psf))
    g /= g.sum()
    fine = np.apply_along_axis(lambda v: np.convolve(v, g, mode="same"), 1, fine)
    fine = np.apply_along_axis(lambda v: np.convolve(v, g, mode="same"), 0, fine)
    centres = (np.arange(n) + 0.5) * h - 0.5
    diff = 0.0
    for fill in ([0.75, 0.875], [1.0, 1.0]):  # aperture edges on the 1/32 grid
        dfs, diag = _single_dot("disk", psf, fill)
        out = np.zeros((40, 41))
        for jj in range(12, 28):
            wy = (np.abs(centres - jj) < 0.5 * fill[1]).astype(float)
            for ii in range(12, 29):
                wx = (np.abs(centres - ii) < 0.5 * fill[0]).astype(float)
                out[jj, ii] = wy @ fine[:n, :n] @ wx / (wy.sum() * wx.sum())
        diff = max(diff, np.abs(dfs[12:28, 12:29] - out[12:28, 12:29]).max())
    dfs1, _ = _single_dot("disk", psf, [1, 1])
    vol_err = abs(dfs1.sum() / vol_d - 1)
    check("blurred disk (strip method) vs brute-force 32x supersampling (fill 0.75x0.875 and 1x1)",
          diff < 5e-4 and vol_err < 1e-9,
          f"max |diff| = {diff:.1e} (depth 0.6; limit 5e-4), volume rel. error {vol_err:.1e} "
          f"({diag['render_method']})")


def _spec(**kw):
    s = {"name": "selfcheck", "seed": 7, "width": 320, "height": 256, "scale_px_per_mm": 13.0,
         "white_level_dn": 30000, "gain_e_per_dn": 0.5, "read_noise_dn": 20,
         "patterns": [{"label": "a", "profile": "gaussian", "dot_diameter_mm": 0.3, "dot_spacing_mm": 0.6,
                       "contrast": 0.5}],
         "moves": [], "step_series": [], "repeats": 1,
         "render": {"overlap_samples": 2000}}
    s.update(kw)
    return s


def check_pure_moves(tmp):
    cases = [
        ("gaussian, psf 0.6, fill 0.8x0.9", {"profile": "gaussian", "dot_diameter_mm": 0.3, "dot_spacing_mm": 0.6,
                                           "contrast": 0.5}, {"psf_sigma_px": 0.6, "fill_factor": [0.8, 0.9]}),
        ("hard disks, exact area", {"profile": "disk", "dot_diameter_mm": 0.3, "dot_spacing_mm": 0.45,
                                    "contrast": 0.6}, {}),
        ("disks, psf 0.5 + edge softness", {"profile": "disk", "dot_diameter_mm": 0.3, "dot_spacing_mm": 0.45,
                                            "contrast": 0.6, "edge_softness_mm": 0.02}, {"psf_sigma_px": 0.5}),
    ]
    for i, (name, pat, eff) in enumerate(cases):
        pat = dict(pat, label="p")
        spec = _spec(patterns=[pat], effects=eff,
                     moves=[{"id": "m", "dx_mm": 1.2345, "dy_mm": -0.6789}],
                     step_series=[{"id": "s", "dx_step_mm": 0.0077, "dy_step_mm": 0.0031, "count": 1}],
                     stage={"constant_offset_px": [0.0, 0.4], "travel_scale": 1.001, "misalign_rad": 0.004,
                            "repeatability_um": 10.0, "per_run_offsets_px": {"p-m": [0.05, -0.03]}})
        d = Path(tmp) / f"move{i}"
        truth = G.generate(spec, d)
        ref = read(d, "p_ref.tif")
        errs = []
        for run, fname in (("p-m", "p_m.tif"), ("p-s1", "p_s1.tif")):
            t = next(r for r in truth["runs"] if r["id"] == run)
            meas = measure_global_shift(ref, read(d, fname))
            errs.append(np.abs(meas - np.array(t["actual_move_px"])).max())
        e = max(errs)
        check(f"pure move measured = truth ({name})", e < 0.02,
              f"max |measured − true| = {e:.4f} px over moves of "
              f"{np.round(next(r for r in truth['runs'] if r['id'] == 'p-m')['actual_move_px'], 3).tolist()} "
              f"and 0.1 px (limit 0.02)")
    return truth


def check_stage_formula(truth):
    spec = truth["spec"]
    st = spec["stage"]
    s = spec["scale_px_per_mm"]
    worst = 0.0
    for r in truth["runs"]:
        cmd = np.array(r["commanded_mm"])
        rnd = np.array(r["offset_px"]["random"])
        expect = s * st["travel_scale"] * (G.rot(st["misalign_rad"]) @ cmd) + np.array(st["constant_offset_px"]) \
            + rnd + np.array(st["per_run_offsets_px"].get(r["id"], [0, 0]))
        worst = max(worst, np.abs(expect - np.array(r["actual_move_px"])).max())
    sig = st["repeatability_um"] * s / 1000
    check("stage model in truth.json", worst < 1e-12,
          f"max |formula − truth| = {worst:.1e} px; random offsets σ = {sig:.3f} px")


def check_intensity(tmp):
    # dense Gaussian print: mean and std against Campbell's theorem for the Poisson dot process
    spec = _spec(noise=False, width=480, height=400,
                 patterns=[{"label": "a", "profile": "gaussian", "dot_diameter_mm": 0.3, "dot_spacing_mm": 0.6,
                            "contrast": 0.4}],
                 effects={"psf_sigma_px": 0.7, "fill_factor": [0.9, 0.8]}, moves=[{"id": "m", "dx_mm": 0.5, "dy_mm": 0}])
    d = Path(tmp) / "intensity"
    truth = G.generate(spec, d)
    img = read(d, "a_ref.tif").astype(float)
    st = truth["patterns"][0]["statistics"]
    rho = st["density_per_mm2"] / 13.0 ** 2  # per px²
    s_img = 13.0 * 0.3 / G.FWHM_PER_SIGMA
    c = 0.4
    vol = c * 2 * math.pi * s_img ** 2
    white = 30000.0
    mean_pred = white * (1 - rho * vol)
    # Campbell: var = ρ ∫ f², f = dot ⊗ psf ⊗ aperture; separable, computed on a fine 1D grid
    st_tot = math.hypot(s_img, 0.7)
    amp = vol / (2 * math.pi * st_tot ** 2)
    x = np.arange(-40, 40, 0.01)
    int_f2 = 1.0
    for f in (0.9, 0.8):
        g = np.exp(-x * x / (2 * st_tot ** 2))
        n = int(round(f / 0.01))
        box = np.ones(n) / n
        gb = np.convolve(g, box, mode="same")
        int_f2 *= (gb * gb).sum() * 0.01
    std_pred = white * math.sqrt(rho * amp ** 2 * int_f2)
    em = img.mean() / mean_pred - 1
    es = img.std() / std_pred - 1
    clipped = truth["frames"]["a_ref.tif"]["pixels_clipped_below_0"]
    check("mean level and contrast (Gaussian print, Campbell's theorem)", abs(em) < 0.01 and abs(es) < 0.06,
          f"mean {img.mean():.1f} DN vs {mean_pred:.1f} ({em * 100:+.2f} %), std {img.std():.1f} vs "
          f"{std_pred:.1f} ({es * 100:+.2f} %), {clipped} pixels clipped (limits 1 %, 6 %)")
    # exact: Σ over pixels = Σ_j vol_j · (share of dot j's blurred mass inside the frame), from the dot list
    dots = np.load(d / "truth_dots" / "a.npy")
    W, H = 480, 400
    ax, ay = (W - 1) / 2, (H - 1) / 2
    cx, cy = ax + 13.0 * dots[:, 0], ay + 13.0 * dots[:, 1]
    inside = ((G.norm_cdf((W - 0.5 - cx) / st_tot) - G.norm_cdf((-0.5 - cx) / st_tot))
              * (G.norm_cdf((H - 0.5 - cy) / st_tot) - G.norm_cdf((-0.5 - cy) / st_tot)))
    exact = white * (1 - vol * inside.sum() / (W * H))
    ee = img.mean() / exact - 1
    check("mean level exact from the dot list (Gaussian print, positions and volume)", abs(ee) < 2e-5 * (1 + clipped),
          f"mean {img.mean():.3f} DN vs {exact:.3f} DN ({ee:+.1e}; {clipped} clipped pixels)")
    # hard disks: mean = white (1 − c · area fraction), exact for non-overlapping disks
    spec = _spec(noise=False, width=480, height=400, patterns=[
        {"label": "b", "profile": "disk", "dot_diameter_mm": 0.3, "dot_spacing_mm": 0.45, "contrast": 0.8}],
        moves=[{"id": "m", "dx_mm": 0.5, "dy_mm": 0}])
    d = Path(tmp) / "intensity_disk"
    truth = G.generate(spec, d)
    img = read(d, "b_ref.tif").astype(float)
    frac = truth["patterns"][0]["statistics"]["area_fraction_covered"]
    pred = white * (1 - 0.8 * frac)
    e = img.mean() / pred - 1
    nn = truth["patterns"][0]["statistics"]["min_centre_distance_mm"]
    dots = np.load(d / "truth_dots" / "b.npy")
    W, H = 480, 400
    cx, cy = (W - 1) / 2 + 13.0 * dots[:, 0], (H - 1) / 2 + 13.0 * dots[:, 1]
    area = G.disk_rect_area(cx, cy, 13.0 * dots[:, 2] / 2, -0.5, W - 0.5, -0.5, H - 0.5).sum()
    exact = white * (1 - 0.8 * area / (W * H))
    ee = img.mean() / exact - 1
    check("mean level of a disk print: white·(1 − c·area fraction) and exact from the dot list; no overlap",
          abs(e) < 0.01 and abs(ee) < 2e-5 and nn > 0.3,
          f"mean {img.mean():.2f} DN vs field-average {pred:.1f} ({e * 100:+.2f} %) and exact {exact:.2f} "
          f"({ee:+.1e}); min centre distance {nn:.4f} mm > diameter 0.3 mm")
    # white level: a sparse, faint print is white almost everywhere
    spec = _spec(patterns=[{"label": "w", "profile": "gaussian", "dot_diameter_mm": 0.3, "dot_spacing_mm": 3.0,
                            "contrast": 0.3}], moves=[{"id": "m", "dx_mm": 0.5, "dy_mm": 0}], repeats=0)
    d = Path(tmp) / "white"
    G.generate(spec, d)
    img = read(d, "w_ref.tif").astype(float)
    e = np.median(img) / white - 1
    check("white level (median of a sparse print)", abs(e) < 0.005,
          f"median {np.median(img):.1f} DN vs white_level_dn {white:.0f} ({e * 100:+.3f} %)")


def check_noise(tmp):
    for bits, white, gain, rn in ((16, 30000.0, 0.5, 20.0), (8, 200.0, 20.0, 1.5)):
        spec = _spec(bit_depth=bits, white_level_dn=white, gain_e_per_dn=gain, read_noise_dn=rn,
                     moves=[{"id": "m", "dx_mm": 0.5, "dy_mm": 0}], repeats=2)
        d = Path(tmp) / f"noise{bits}"
        G.generate(spec, d)
        a = read(d, "a_ref.tif").astype(float)
        b = read(d, "a_ref_r1.tif").astype(float)
        c = read(d, "a_ref_r2.tif").astype(float)
        # noise-free signal via the generator's own renderer is not used: the mean of three frames
        S = (a + b + c) / 3
        meas = 0.5 * ((a - b).var() + (a - c).var()) / 2
        pred = (S.mean() / gain + rn * rn + 1.0 / 12.0)
        e = meas / pred - 1
        check(f"noise: var(ref − repeat)/2 vs S/gain + read² + 1/12 ({bits}-bit)", abs(e) < 0.03,
              f"measured {meas:.2f} DN², predicted {pred:.2f} DN² ({e * 100:+.2f} %, limit 3 %)")


def check_hardware_readout():
    """The camera's own read-out on flat and ramp irradiances: block geometry, means, and the
    noise of one output pixel against photon transfer (Janesick 2007): digital binning
    (S/g + r² + 1/12)/n + 1/12, charge binning S/(n g) + r²/n² + 1/12, decimation S/g + r² + 1/12."""
    spec = G.effective_spec(_spec(white_level_dn=30000.0, gain_e_per_dn=1.0, read_noise_dn=25.0))
    rng = np.random.default_rng(5)
    irr = np.full((512, 512), 0.02)
    m = 30000.0 * 0.02
    worst = 0.0
    details = []
    for ro, mean, var in (
        ({"name": "d", "binning": [2, 2], "domain": "digital"}, m, (m + 625 + 1 / 12) / 4 + 1 / 12),
        ({"name": "c", "binning": [2, 2], "domain": "charge"}, m, m / 4 + 625 / 16 + 1 / 12),
        ({"name": "s", "binning": [2, 2], "domain": "charge", "value": "sum"}, 4 * m, 4 * m + 625 + 1 / 12),
        ({"name": "x", "decimation": [2, 2]}, m, m + 625 + 1 / 12),
    ):
        out = G.read_out(irr, spec, rng, ro).astype(float)
        e = max(abs(out.mean() / mean - 1), abs(out.var() / var - 1))
        worst = max(worst, e)
        details.append(f"{ro['name']}: var {out.var():.1f} vs {var:.1f}")
    quiet = dict(spec, noise=False)
    ramp = np.tile(np.arange(64.0) / 64.0, (8, 1))
    dec = G.read_out(ramp, quiet, rng, {"name": "x", "decimation": [2, 1]}).astype(float)
    binned = G.read_out(ramp, quiet, rng, {"name": "b", "binning": [2, 1]}).astype(float)
    pixel = np.rint(30000.0 * np.arange(64) / 64.0)  # each sensor pixel digitised (digital binning)
    want_dec = pixel[0::2]
    want_bin = np.rint((pixel[0::2] + pixel[1::2]) / 2)
    geometry = np.array_equal(dec[0], want_dec) and np.array_equal(binned[0], want_bin)
    check("hardware read-out: first pixel kept, block averaged, noise per photon transfer",
          worst < 0.03 and geometry, f"{'; '.join(details)}; worst {worst * 100:.2f} % (limit 3 %), geometry {geometry}")


def check_vignetting(tmp):
    v = 0.35
    W, H = 480, 400
    spec = _spec(width=W, height=H, effects={"vignetting_v": v},
                 patterns=[{"label": "w", "profile": "gaussian", "dot_diameter_mm": 0.3, "dot_spacing_mm": 4.0,
                            "contrast": 0.05}], moves=[{"id": "m", "dx_mm": 0.5, "dy_mm": 0}], repeats=0)
    d = Path(tmp) / "vignetting"
    G.generate(spec, d)
    img = read(d, "w_ref.tif").astype(float)
    ax, ay = (W - 1) / 2, (H - 1) / 2
    r0sq = 0.25 * (W * W + H * H)
    b = 32

    def block(x0, y0):
        ys, xs = np.mgrid[y0:y0 + b, x0:x0 + b]
        V = 1 - v * ((xs - ax) ** 2 + (ys - ay) ** 2) / r0sq
        return np.median(img[y0:y0 + b, x0:x0 + b]), float(V.mean())

    mc, vc = block(int(ax) - b // 2, int(ay) - b // 2)
    worst = 0.0
    txt = []
    for x0, y0 in ((0, 0), (W - b, 0), (0, H - b), (W - b, H - b)):
        m, vv = block(x0, y0)
        e = (m / mc) / (vv / vc) - 1
        worst = max(worst, abs(e))
        txt.append(f"{m / mc:.4f}")
    check("vignetting ratio corner/centre", worst < 0.003,
          f"measured {', '.join(txt)} vs model {vv / vc:.4f} (worst {worst * 100:.2f} %, limit 0.3 %)")


def check_geometry(tmp):
    # distortion: same print rendered without and with k1 (noise-free), local shifts at subsets
    W, H = 480, 400
    base = _spec(width=W, height=H, noise=False, effects={"psf_sigma_px": 0.5})
    spec0 = G.effective_spec(base)
    k1_norm = -0.004
    spec1 = G.effective_spec(dict(base, effects={"psf_sigma_px": 0.5, "k1_norm": k1_norm}))
    cam0, cam1 = G.Camera(spec0), G.Camera(spec1)
    pr = G.Print(spec0["patterns"][0], 3, (-22, 22, -19, 19), spec0["render"])
    fr = G.Frame("t", "reference", np.eye(2), np.zeros(2), 1.0, 0.0)
    a, _ = G.render_irradiance(cam0, pr, fr, spec0["render"])
    b, _ = G.render_irradiance(cam1, pr, fr, spec1["render"])
    def dist_field(x, y):
        ux, uy = x - cam0.axis[0], y - cam0.axis[1]
        r2 = ux * ux + uy * uy
        return cam1.k1 * r2 * ux, cam1.k1 * r2 * uy

    worst, pts, naive = 0.0, 0, 0.0
    for cx, cy in ((100, 100), (380, 100), (100, 300), (380, 300), (240, 200), (240, 60), (60, 200)):
        meas, exp = measure_local_shift(a, b, cx, cy, dist_field)
        worst = max(worst, np.abs(meas - exp).max())
        naive = max(naive, np.abs(meas - np.array(dist_field(np.array([cx]), np.array([cy]))).ravel()).max())
        pts += 1
    corner = abs(k1_norm) * cam1.r0
    check("radial distortion: local shifts = k1·r²·u (k1_norm −0.004)", worst < 0.005,
          f"max |measured − model| = {worst:.4f} px at {pts} subsets (vs the field at the subset centre: "
          f"{naive:.4f}); corner shift ≈ {corner:.2f} px; limit 0.005")
    # rotation + scale change + move of the deformed frame, measured on the written files
    th, ds = 0.002, 0.0015
    spec = _spec(width=W, height=H, noise=False, effects={"psf_sigma_px": 0.5, "rotation_rad": th, "scale_ds": ds},
                 moves=[{"id": "m", "dx_mm": 0.3, "dy_mm": -0.2}], repeats=0)
    d = Path(tmp) / "rotation"
    truth = G.generate(spec, d)
    ref, mov = read(d, "a_ref.tif"), read(d, "a_m.tif")
    run = truth["runs"][0]
    A, bb = np.array(run["image_map_undistorted"]["A"]), np.array(run["image_map_undistorted"]["b"])
    axis = np.array(truth["conventions"]["optical_axis_px"])
    def affine_field(x, y):
        return (A[0, 0] * (x - axis[0]) + A[0, 1] * (y - axis[1]) + bb[0],
                A[1, 0] * (x - axis[0]) + A[1, 1] * (y - axis[1]) + bb[1])

    worst = 0.0
    for cx, cy in ((100, 100), (380, 100), (100, 300), (380, 300), (240, 200)):
        meas, exp = measure_local_shift(ref, mov, cx, cy, affine_field)
        worst = max(worst, np.abs(meas - exp).max())
    # sign convention: +θ turns +x toward +y, so a point right of the axis moves down (+y)
    right = A @ np.array([150.0, 0.0])
    check("rotation (+θ turns +x toward +y) and scale change about the axis", worst < 0.005 and right[1] > 0,
          f"max |measured − model| = {worst:.4f} px at 5 subsets (θ = {th}, ds = {ds}; limit 0.005); "
          f"a point 150 px right of the axis moves by {np.round(right, 3).tolist()} + b")


# --- tilt, Brown–Conrady decentring, bow, byte identity (own formulas, own inverse) --------------

def _subsets(W, H, t, half=48, pad=12):
    """3x3 subset centres spread over the frame such that the subset and its moved twin (by t px)
    both lie inside the frame."""
    tx, ty = (int(math.ceil(abs(v))) for v in t)
    xs = np.linspace(half + pad + (tx if t[0] < 0 else 0), W - half - pad - (tx if t[0] > 0 else 0), 3)
    ys = np.linspace(half + pad + (ty if t[1] < 0 else 0), H - half - pad - (ty if t[1] > 0 else 0), 3)
    return [(int(round(x)), int(round(y))) for y in ys for x in xs]


def _tilt_pair(tmp, name, eff, move_mm):
    spec = _spec(width=640, height=540, noise=False, working_distance_mm=300.0,
                 effects=dict(eff, psf_sigma_px=0.5), repeats=0,
                 moves=[{"id": "m", "dx_mm": move_mm[0], "dy_mm": move_mm[1]}])
    d = Path(tmp) / name
    truth = G.generate(spec, d)
    return truth, read(d, "a_ref.tif"), read(d, "a_m.tif")


def check_tilt(tmp):
    """A tilted target (pinhole, Z = 300 mm), a 5 mm move in the target's plane: local shifts vs the
    first-order formula u = t − a(2 px tx + tx², px ty + py tx + tx ty) − b(px ty + py tx + tx ty,
    2 py ty + ty²), a = tan θy/(Z·scale), b = tan θx/(Z·scale), plus the O(θ²) foreshortening
    (cos θ − 1)·t along the tilted axis that this formula leaves out (−0.0099 px for 65 px at 1°)."""
    th = math.radians(1.0)
    for label, eff, move in (("θy = 1°, 5 mm x move", {"tilt_about_y_rad": th}, (5.0, 0.0)),
                             ("θx = 1°, 5 mm y move", {"tilt_about_x_rad": th}, (0.0, 5.0))):
        truth, ref, mov = _tilt_pair(tmp, "tilt_" + ("y" if "θy" in label else "x"), eff, move)
        e = truth["effects"]
        a, b = e["tilt_a_per_px"], e["tilt_b_per_px"]
        Z, scale = 300.0, 13.0
        ok_ab = (abs(a - math.tan(e["tilt_about_y_rad"]) / (Z * scale)) < 1e-18
                 and abs(b - math.tan(e["tilt_about_x_rad"]) / (Z * scale)) < 1e-18)
        tx, ty = truth["runs"][0]["actual_move_px"]
        ax, ay = truth["conventions"]["optical_axis_px"]
        fx_ = math.cos(e["tilt_about_y_rad"]) - 1.0
        fy_ = math.cos(e["tilt_about_x_rad"]) - 1.0

        def first_order(x, y, fore=True):
            px, py = x - ax, y - ay
            ux = tx - a * (2 * px * tx + tx * tx) - b * (px * ty + py * tx + tx * ty)
            uy = ty - a * (px * ty + py * tx + tx * ty) - b * (2 * py * ty + ty * ty)
            if fore:
                ux, uy = ux + fx_ * tx, uy + fy_ * ty
            return ux, uy

        worst, worst_raw, span = 0.0, 0.0, 0.0
        subsets = _subsets(640, 540, (tx, ty))
        for cx, cy in subsets:
            meas, exp = measure_local_shift(ref, mov, cx, cy, first_order)
            _, exp_raw = measure_local_shift(ref, mov, cx, cy, lambda x, y: first_order(x, y, False))
            worst = max(worst, np.abs(meas - exp).max())
            worst_raw = max(worst_raw, np.abs(meas - exp_raw).max())
            span = max(span, np.abs(meas - np.array([tx, ty])).max())
        check(f"tilt {label}: local shifts vs first-order formula (+ foreshortening)", worst < 0.003 and ok_ab,
              f"max |measured − formula| = {worst:.4f} px at {len(subsets)} subsets (limit 0.003); "
              f"without the (cos θ − 1)·t term {worst_raw:.4f} px; tilt effect up to {span:.3f} px; "
              f"a = {a:.4e}, b = {b:.4e} /px")


def _bc_forward(x, e, r0, k1, k2, p1, p2):
    """Brown–Conrady from the definition: absolute px → distorted absolute px."""
    qx, qy = (x[..., 0] - e[0]) / r0, (x[..., 1] - e[1]) / r0
    r2 = qx * qx + qy * qy
    rad = k1 * r2 + k2 * r2 * r2
    dx = qx * rad + 2 * p1 * qx * qy + p2 * (r2 + 2 * qx * qx)
    dy = qy * rad + p1 * (r2 + 2 * qy * qy) + 2 * p2 * qx * qy
    return x + r0 * np.stack([dx, dy], axis=-1)


def _bc_inverse(xd, *args):
    """Own inverse: fixed-point x ← x_d − (distort(x) − x) (a contraction for mild distortion)."""
    x = np.array(xd, float)
    for _ in range(500):
        nx = xd - (_bc_forward(x, *args) - x)
        if np.abs(nx - x).max() < 1e-12:
            return nx
        x = nx
    return x


def check_decentring(tmp):
    """k2, p1, p2 and a decentred distortion centre on a moved pair: local shifts vs the exact mapping
    difference distort(undistort(x) + t) − x, with our own forward model and fixed-point inverse."""
    W, H = 640, 540
    dist = {"k1_norm": -0.004, "k2_norm": 0.01, "p1_norm": 0.001, "p2_norm": -0.0015,
            "distortion_centre_px": [15.0, -10.0]}
    spec = _spec(width=W, height=H, noise=False, effects=dict(dist, psf_sigma_px=0.5), repeats=0,
                 moves=[{"id": "m", "dx_mm": 2.0, "dy_mm": -1.5}])
    d = Path(tmp) / "decentring"
    truth = G.generate(spec, d)
    ref, mov = read(d, "a_ref.tif"), read(d, "a_m.tif")
    e = truth["effects"]
    axis = np.array(truth["conventions"]["optical_axis_px"])
    r0 = 0.5 * math.hypot(W, H)
    args = (axis + np.array(dist["distortion_centre_px"]), r0, dist["k1_norm"], dist["k2_norm"],
            dist["p1_norm"], dist["p2_norm"])
    t = np.array(truth["runs"][0]["actual_move_px"])
    ok_truth = (abs(e["k2_per_px4"] * r0 ** 4 - 0.01) < 1e-15 and abs(e["p1_per_px"] * r0 - 0.001) < 1e-15
                and e["distortion_centre_abs_px"] == args[0].tolist())

    def field(x, y):
        xd = np.stack([x, y], axis=-1)
        xu = _bc_inverse(xd, *args)
        out = _bc_forward(xu + t, *args) - xd
        return out[..., 0], out[..., 1]

    worst, span = 0.0, 0.0
    subsets = _subsets(W, H, t)
    for cx, cy in subsets:
        meas, exp = measure_local_shift(ref, mov, cx, cy, field)
        worst = max(worst, np.abs(meas - exp).max())
        span = max(span, np.abs(meas - t).max())
    # the generator's own inverse (used for the print's bounds) to 1e-9 px
    cam = G.Camera(G.effective_spec(spec))
    pts = np.random.default_rng(3).uniform([-0.5, -0.5], [W - 0.5, H - 0.5], (4000, 2))
    inv_err = np.abs(cam.distort(cam.undistort(pts - axis)) - (pts - axis)).max()
    own_err = np.abs(cam.distort(cam.undistort(pts - axis)) + axis - _bc_forward(
        _bc_inverse(pts, *args), *args)).max()
    fwd_err = np.abs(cam.distort(pts - axis) + axis - _bc_forward(pts, *args)).max()
    check("Brown–Conrady k2, p1, p2, decentred: local shifts vs exact mapping difference",
          worst < 0.005 and inv_err < 1e-9 and fwd_err < 1e-9 and ok_truth,
          f"max |measured − model| = {worst:.4f} px at {len(subsets)} subsets (limit 0.005); distortion "
          f"changes the move by up to {span:.3f} px; generator forward vs definition {fwd_err:.1e} px, "
          f"its inverse round trip {inv_err:.1e} px ({own_err:.1e})")


def check_bow(tmp):
    """A bowed target (κ = 1e-3 /mm, apex moving with the print), no tilt: local shifts vs our own
    closed form (ref: |P| from the quadratic ρ'(Z + κρ²/2) = scale·Z·ρ; moved: scale·Z·(P + t/scale)/(Z + κ|P|²/2))."""
    kappa, Z, scale = 1e-3, 300.0, 13.0
    spec = _spec(width=640, height=540, noise=False, working_distance_mm=Z, state_working_distance=True,
                 effects={"target_bow_per_mm": kappa, "psf_sigma_px": 0.5}, repeats=0,
                 moves=[{"id": "m", "dx_mm": 5.0, "dy_mm": 0.0}])
    d = Path(tmp) / "bow"
    truth = G.generate(spec, d)
    ref, mov = read(d, "a_ref.tif"), read(d, "a_m.tif")
    ax, ay = truth["conventions"]["optical_axis_px"]
    t = np.array(truth["runs"][0]["actual_move_px"])

    def field(x, y):
        px, py = x - ax, y - ay
        rho_img = np.hypot(px, py)
        rho = 2 * rho_img * Z / (scale * Z + np.sqrt((scale * Z) ** 2 - 2 * rho_img ** 2 * kappa * Z))
        f = np.where(rho_img > 0, rho / np.where(rho_img > 0, rho_img, 1), 1 / scale)
        Px, Py = px * f, py * f
        den = Z + 0.5 * kappa * (Px * Px + Py * Py)
        return scale * Z * (Px + t[0] / scale) / den - px, scale * Z * (Py + t[1] / scale) / den - py

    worst, span = 0.0, 0.0
    subsets = _subsets(640, 540, t)
    for cx, cy in subsets:
        meas, exp = measure_local_shift(ref, mov, cx, cy, field)
        worst = max(worst, np.abs(meas - exp).max())
        span = max(span, np.abs(meas - t).max())
    man = json.loads((d / "dataset.json").read_text())
    ok = man.get("working_distance_mm") == Z and truth["effects"]["target_bow_per_mm"] == kappa
    check("bowed target (κ = 1e-3 /mm, not in ffdic's catalogue): local shifts vs own closed form",
          worst < 0.005 and ok,
          f"max |measured − model| = {worst:.4f} px at {len(subsets)} subsets (limit 0.005); bow changes the "
          f"move by up to {span:.3f} px; manifest working_distance_mm = {man.get('working_distance_mm')}")


# sha256 over (name, bytes) of the TIFFs and dataset.json of BYTE_IDENTITY_SPEC, computed with
# generate.py as it was before the tilt / Brown–Conrady / bow keys were added.
BYTE_IDENTITY_SPEC = {
    "name": "byte-identity", "seed": 19, "width": 200, "height": 160, "scale_px_per_mm": 13.0,
    "patterns": [{"label": "g", "profile": "gaussian", "dot_diameter_mm": 0.3, "dot_spacing_mm": 0.5,
                  "contrast": 0.6},
                 {"label": "k", "profile": "disk", "dot_diameter_mm": 0.25, "dot_spacing_mm": 0.4,
                  "contrast": 0.8, "edge_softness_mm": 0.01}],
    "moves": [{"id": "m", "dx_mm": 1.3, "dy_mm": -0.7, "rotation_rad": 0.003, "scale_ds": 0.001}],
    "step_series": [{"id": "s", "dx_step_mm": 0.0077, "dy_step_mm": 0.0, "count": 1}],
    "repeats": 1, "stated_repeatability_um": 20.0,
    "stage": {"constant_offset_px": [0.0, 0.4], "repeatability_um": 3.0},
    "effects": {"k1_norm": -0.004, "psf_sigma_px": 0.6, "vignetting_v": 0.3, "fill_factor": [0.9, 0.8]},
    "render": {"overlap_samples": 2000}}
BYTE_IDENTITY_SHA256 = "c19ca7d46d50f6c0f12fdf4572a14d9c58c7298f68fb0e362da115074bd04fe5"


def check_byte_identity(tmp):
    d = Path(tmp) / "byte_identity"
    G.generate(BYTE_IDENTITY_SPEC, d)
    h = hashlib.sha256()
    for n in sorted(os.listdir(d)):
        if n.endswith(".tif") or n == "dataset.json":
            h.update(n.encode())
            h.update((d / n).read_bytes())
    got = h.hexdigest()
    check("old-style spec (k1 only) byte-identical to the generator before tilt/Brown–Conrady/bow",
          got == BYTE_IDENTITY_SHA256, f"sha256 of 8 TIFFs + dataset.json {got[:16]}… "
          f"(expected {BYTE_IDENTITY_SHA256[:16]}…)")


def check_illumination_gain(tmp):
    spec = _spec(width=160, height=128, noise=False, effects={"illumination_gain": 0.97, "vignetting_v": 0.2},
                 moves=[{"id": "z", "dx_mm": 0.0, "dy_mm": 0.0}, {"id": "g", "dx_mm": 0.0, "dy_mm": 0.0,
                                                                  "illumination_gain": 1.04}], repeats=0)
    d = Path(tmp) / "gain"
    G.generate(spec, d)
    ref = read(d, "a_ref.tif").astype(float)
    r1 = read(d, "a_z.tif").astype(float).sum() / ref.sum()
    r2 = read(d, "a_g.tif").astype(float).sum() / ref.sum()
    check("illumination_gain on deformed frames only (global and per move)",
          abs(r1 - 0.97) < 1e-5 and abs(r2 - 1.04) < 1e-5, f"frame/reference = {r1:.6f} (0.97), {r2:.6f} (1.04)")


def check_dataset_files(tmp, truth_dir):
    d = Path(truth_dir)
    man = json.loads((d / "dataset.json").read_text())
    ok = man["format"] == "ffdic-dataset/1" and man["camera"]["bit_depth"] in (8, 16)
    problems = []
    names = set()
    for r in man["runs"]:
        names.update([r["reference"], r["deformed"], *r.get("repeat", [])])
    for n in sorted(names):
        with tifffile.TiffFile(d / n) as tf:
            p = tf.pages[0]
            if len(tf.pages) != 1 or tf.byteorder != "<" or p.compression != 1 or p.photometric != 1 \
                    or p.dtype not in (np.uint16, np.uint8) or p.shape != (man["camera"]["height"], man["camera"]["width"]):
                problems.append(n)
    check("dataset.json and TIFFs (single page, uncompressed, LE, minisblack, size)", ok and not problems,
          f"{len(names)} TIFFs checked, problems: {problems or 'none'}")
    # characterised print fields
    spec = _spec(width=160, height=128, state_print="characterised", stated_repeatability_um=20.0,
                 patterns=[{"label": "g", "profile": "gaussian", "dot_diameter_mm": 0.3, "dot_spacing_mm": 0.6,
                            "contrast": 0.5},
                           {"label": "k", "profile": "disk", "dot_diameter_mm": 0.25, "dot_spacing_mm": 0.4,
                            "contrast": 0.8, "diameter_cv": 0.05, "edge_softness_mm": 0.01}],
                 moves=[{"id": "x1mm", "dx_mm": 1.0, "dy_mm": 0.0}],
                 step_series=[{"id": "xs", "dx_step_mm": 0.0077, "dy_step_mm": 0.0, "count": 2}])
    d2 = Path(tmp) / "characterised"
    G.generate(spec, d2)
    m2 = json.loads((d2 / "dataset.json").read_text())
    ids = [r["id"] for r in m2["runs"]]
    pg = m2["runs"][0]["pattern"]
    pk = m2["runs"][-1]["pattern"]
    sg = 0.3 / G.FWHM_PER_SIGMA
    f_last, m_last = pg["mtf"][-1]
    ok = (ids == ["g-x1mm", "g-xs1", "g-xs2", "k-x1mm", "k-xs1", "k-xs2"]
          and len(pg["mtf"]) == 15 and abs(pg["mtf"][0][1] - 1) < 1e-12 and abs(f_last - 6.5) < 1e-12
          and abs(m_last - math.exp(-2 * math.pi ** 2 * sg ** 2 * f_last ** 2)) < 1e-12
          and pk["profile"] == "disk" and pk["edge_softness_mm"] == 0.01 and m2["stage_repeatability_um"] == 20.0
          and m2["runs"][1]["stage"]["dx_mm"] == 0.0077 and m2["runs"][2]["stage"]["dx_mm"] == 0.0154
          and m2["runs"][0]["repeat"] == ["g_ref_r1.tif"])
    check("characterised manifest (run ids, mtf 0..Nyquist in 15 points, profile fields)", ok,
          f"runs {ids}; gaussian mtf at {f_last:.2f} cyc/mm = {m_last:.4f}")
    # determinism and refusal to overwrite
    d3 = Path(tmp) / "characterised_again"
    G.generate(spec, d3)

    def digest(p):
        return hashlib.sha256(b"".join((p / n).read_bytes() for n in sorted(os.listdir(p)) if n.endswith(".tif"))).hexdigest()

    same = digest(d2) == digest(d3)
    refused = False
    try:
        G.generate(spec, d2)
    except FileExistsError:
        refused = True
    G.generate(dict(spec, overwrite=True), d2)
    check("deterministic output; refuses a non-empty folder unless overwrite", same and refused and digest(d2) == digest(d3),
          f"identical TIFFs: {same}; refused: {refused}")


def check_cli_and_sample3(tmp):
    spec = _spec(width=96, height=80, moves=[{"id": "m", "dx_mm": 0.2, "dy_mm": 0}])
    sp = Path(tmp) / "cli_spec.json"
    sp.write_text(json.dumps(spec))
    out = Path(tmp) / "cli_out"
    r = subprocess.run([sys.executable, str(HERE / "generate.py"), str(sp), str(out), "--quiet"],
                       capture_output=True, text=True)
    r2 = subprocess.run([sys.executable, str(HERE / "generate.py"), str(sp), str(out), "--quiet"],
                        capture_output=True, text=True)
    check("CLI generate.py SPEC OUT_DIR (and refusal on rerun)", r.returncode == 0 and (out / "truth.json").exists()
          and r2.returncode != 0, f"first rc {r.returncode}, second rc {r2.returncode}: {r2.stderr.strip()[:80]}")
    src = HERE.parents[2] / "shared" / "data" / "dic-challenge-1" / "sample3"
    if not src.is_dir():
        check("sample3_dataset.py", True, f"skipped: {src} not present")
        return
    out = Path(tmp) / "sample3"
    r = subprocess.run([sys.executable, str(HERE / "sample3_dataset.py"), str(out)], capture_output=True, text=True)
    ok = r.returncode == 0
    detail = r.stderr.strip()[-200:]
    if ok:
        man = json.loads((out / "dataset.json").read_text())
        ref = read(out, "reference.tif").astype(float)
        s3 = read(out, man["runs"][2]["deformed"]).astype(float)
        meas = measure_global_shift(ref, s3)
        want = np.array([0.3, 0.3])
        e = np.abs(meas - want).max()
        ok = (len(man["runs"]) == 5 and man["runs"][2]["stage"]["dx_mm"] == 0.03
              and man["runs"][0]["repeat"] == ["shift_00.tif"] and e < 0.02
              and read(out, "reference.tif").dtype == np.uint8)
        detail = f"5 runs, shift_03 measured {np.round(meas, 4).tolist()} vs (0.3, 0.3) px (|err| {e:.4f})"
    check("sample3_dataset.py builds the DIC Challenge dataset", ok, detail)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--keep", help="write the test datasets here instead of a temporary folder")
    a = ap.parse_args()
    t0 = time.perf_counter()
    tmp = a.keep or tempfile.mkdtemp(prefix="ffdic-indep-selfcheck-")
    if a.keep and Path(tmp).exists():
        shutil.rmtree(tmp)
    Path(tmp).mkdir(parents=True, exist_ok=True)
    try:
        for fn in (check_special_functions, check_disk_area, check_pixel_centre, check_single_dots,
                   check_hardware_readout):
            t = time.perf_counter()
            fn()
            print(f"    ({time.perf_counter() - t:.1f} s)", flush=True)
        t = time.perf_counter()
        truth = check_pure_moves(tmp)
        check_stage_formula(truth)
        print(f"    ({time.perf_counter() - t:.1f} s)", flush=True)
        for fn in (check_intensity, check_noise, check_vignetting, check_geometry, check_tilt, check_decentring,
                   check_bow, check_byte_identity):
            t = time.perf_counter()
            fn(tmp)
            print(f"    ({time.perf_counter() - t:.1f} s)", flush=True)
        t = time.perf_counter()
        check_illumination_gain(tmp)
        check_dataset_files(tmp, Path(tmp) / "move0")
        check_cli_and_sample3(tmp)
        print(f"    ({time.perf_counter() - t:.1f} s)", flush=True)
    except Exception as e:  # a crash is a failure, reported as such
        import traceback
        traceback.print_exc()
        check("selfcheck ran to the end", False, repr(e))
    finally:
        if not a.keep:
            shutil.rmtree(tmp, ignore_errors=True)
    n_fail = sum(1 for _, ok, _ in RESULTS if not ok)
    print(f"\n{len(RESULTS) - n_fail}/{len(RESULTS)} checks passed in {time.perf_counter() - t0:.1f} s")
    return 1 if n_fail else 0


if __name__ == "__main__":
    sys.exit(main())
