"""ffdic from Python: the DIC engine, fill-factor reductions, the imaging model and the
diagnosis on numpy arrays (``analyze``, ``reduce``, ``render``, ``compare``, ``diagnose``), and
the daemon from a lab script (``Client``).

The heavy calls run in Rust and release the GIL; their numbers are those of the ``ffdic`` CLI
on the same inputs.
"""

from __future__ import annotations

import enum
import json
import os
from typing import Any, Dict, List, Mapping, Optional, Sequence, Tuple, Union

import numpy as np

from . import _ffdic
from ._ffdic import AnalysisResult, decode_tiff, read_image
from .client import Client, Event, JobResult, ProblemError, RunFailed

__version__: str = _ffdic.__version__


def __dir__() -> list:
    """What the package offers (``__all__``), not the modules and type names it imports for
    itself (PEP 562): tab completion and ``dir(ffdic)`` show the API only."""
    return sorted([*__all__, "__version__"])

__all__ = [
    "AnalysisResult",
    "Client",
    "Event",
    "JobResult",
    "ProblemError",
    "RunFailed",
    "Status",
    "analyze",
    "compare",
    "dataset_init",
    "decode_tiff",
    "diagnose",
    "read_image",
    "reduce",
    "render",
]

Status = enum.IntEnum("Status", [(name.upper(), code) for code, name in enumerate(_ffdic.STATUSES)])  # type: ignore[misc]
Status.__doc__ = "Status of a point of interest: the codes of ``AnalysisResult.status``."

Roi = Tuple[int, int, int, int]
SchemeAxis = Union[Tuple[int, int, int], Mapping[str, int]]


def analyze(
    reference: np.ndarray,
    deformed: Union[np.ndarray, Sequence[np.ndarray]],
    *,
    subset: Optional[int] = None,
    step: Optional[int] = None,
    roi: Optional[Roi] = None,
    strain_window: Optional[int] = None,
    interp: Optional[str] = None,
    shape: Optional[str] = None,
    prefilter_sigma: Optional[float] = None,
    min_zncc: Optional[float] = None,
    max_motion: Optional[int] = None,
    max_displacement_std: Optional[float] = None,
    outlier_threshold: Optional[float] = None,
    outlier_test: bool = True,
    mask: Optional[np.ndarray] = None,
    threads: Optional[int] = None,
) -> Union[AnalysisResult, List[AnalysisResult]]:
    """2D DIC of ``deformed`` against ``reference``; with a list of frames, a sequence.

    Both are 2-D numpy arrays of one shape (uint8, uint16, float32 or float64; C- or
    F-ordered). A C-contiguous float32 array is read where it lies, without a copy. Every
    keyword left at ``None`` takes the value of ``ffdic analyze``: subset 41 px (odd), step
    20 px, the centred 800x800 ROI ``(x, y, width, height)``, strain window 7 points,
    ``interp="bspline3"`` (or ``"bspline5"``), ``shape="affine"`` (or ``"quadratic"``),
    pre-filter σ 0.7 px, min ZNCC 0.6, max motion 160 px, max predicted displacement std
    0.1 px, outlier threshold 2 (``outlier_test=False`` turns the test off). ``threads``
    bounds the worker threads (default: every core). Releases the GIL while it runs.

    ``mask`` (one pair only): a 2-D array of the reference's shape, true or non-zero where
    points are analysed (``ffdic analyze --mask``); a point whose centre lies on a masked pixel
    gets the status ``masked`` and is not correlated. ``deformed`` as a list of frames analyses them as a sequence,
    as ``ffdic analyze REF F1 F2 …`` does: each result holds the displacement accumulated
    since ``reference`` at the reference's points, the reference moving on to the previous
    frame when too many points are lost (``AnalysisResult.reference_index`` says which one
    served); a list of results comes back.

    Bad input (not 2-D, shapes that differ, an unsupported dtype, NaN or infinite pixels,
    settings out of range) raises ``ValueError``.
    """
    if mask is not None:
        mask = np.asarray(mask)
        if mask.dtype == np.bool_:
            mask = mask.astype(np.uint8)
    return _ffdic.analyze(
        reference,
        list(deformed) if isinstance(deformed, (list, tuple)) else deformed,
        subset=subset,
        step=step,
        roi=None if roi is None else (int(roi[0]), int(roi[1]), int(roi[2]), int(roi[3])),
        strain_window=strain_window,
        interp=interp,
        shape=shape,
        prefilter_sigma=prefilter_sigma,
        min_zncc=min_zncc,
        max_motion=max_motion,
        max_displacement_std=max_displacement_std,
        outlier_threshold=outlier_threshold,
        outlier_test=outlier_test,
        mask=mask,
        threads=threads,
    )


def _axis(axis: SchemeAxis) -> Dict[str, int]:
    if isinstance(axis, Mapping):
        return {k: int(axis[k]) for k in ("block", "first", "active")}
    block, first, active = axis
    return {"block": int(block), "first": int(first), "active": int(active)}


def reduce(
    frame: np.ndarray,
    scheme: Union[str, Mapping[str, Any]] = "ff50",
    *,
    x: Optional[SchemeAxis] = None,
    y: Optional[SchemeAxis] = None,
) -> np.ndarray:
    """The frame with a lower fill factor synthesised from it (float32).

    ``scheme`` is a preset — ``"ff100"`` (2x2 binning), ``"ff50"`` (rows binned, columns
    subsampled), ``"ff25"`` (both subsampled), ``"native"`` (every pixel) — or
    ``"BXxBY/AXxAY"`` (e.g. ``"2x2/1x2"``: 2x2 blocks whose centred 1x2 pixels are
    light-sensitive), or a scheme per axis: give ``x`` and ``y`` as
    ``(block, first, active)`` (``active`` pixels from ``first`` in every ``block``) and
    ``scheme`` as its name, or a dict ``{"name", "x": {...}, "y": {...}}``.
    """
    if x is not None or y is not None:
        if x is None or y is None:
            raise ValueError("reduce: give both x and y, or neither")
        name = scheme if isinstance(scheme, str) else "custom"
        spec: Union[str, Mapping[str, Any]] = {"name": name, "x": _axis(x), "y": _axis(y)}
    else:
        spec = scheme
    text = spec if isinstance(spec, str) else json.dumps(
        {"name": spec["name"], "x": _axis(spec["x"]), "y": _axis(spec["y"])}
    )
    return _ffdic.reduce(frame, text)


def render(
    experiment: Optional[str] = None,
    model: Optional[str] = None,
    seed: Optional[int] = None,
    *,
    data_dir: str = "data",
) -> Dict[str, Any]:
    """The frames the imaging model renders for an experiment, as ``ffdic simulate`` writes them.

    ``experiment``: a TOML file or TOML text (default: the paper's study). ``model``: a TOML
    file, a model name (embedded, or stored by the daemon in ``data_dir/models``) or TOML text
    (default: ``paper-bench``). Returns ``{"manifest": dict, "frames": {file name: uint16
    array}}``.
    """
    result: Dict[str, Any] = _ffdic.render(experiment, model, seed, data_dir)
    return result


def dataset_init(
    folder: Union[str, "os.PathLike[str]"],
    *,
    scale_px_per_mm: float,
    step_mm: Optional[Tuple[float, float]] = None,
    step_px: Optional[Tuple[float, float]] = None,
    reference: Optional[str] = None,
    repeats: Sequence[str] = (),
    name: Optional[str] = None,
    pattern: Optional[str] = None,
    stage_repeatability_um: Optional[float] = None,
    force: bool = False,
) -> Dict[str, Any]:
    """A folder of frames captured by hand made a dataset: writes ``folder/dataset.json`` as
    ``ffdic dataset init`` does and returns the manifest as a dict.

    The folder's frames (TIFF, PNG or BMP) are one ``reference`` (default: ``reference.tif``, ``ref.tif``, a
    name starting with ``ref``, else the first by name), its static ``repeats`` (the camera's
    noise floor), and the rest in name order as a step series: frame k moved by k steps of
    ``step_mm`` (the stage's move, mm) or ``step_px`` (px, converted with
    ``scale_px_per_mm``). Every problem of the description is named at once (``ValueError``);
    an existing ``dataset.json`` is replaced only with ``force=True``. Then
    ``compare(folder, schemes=["native"])`` gives each step's bias against its commanded move.
    """
    result: Dict[str, Any] = _ffdic.dataset_init(
        folder,
        scale_px_per_mm=scale_px_per_mm,
        step_mm=step_mm,
        step_px=step_px,
        reference=reference,
        repeats=list(repeats),
        name=name,
        pattern=pattern,
        stage_repeatability_um=stage_repeatability_um,
        force=force,
    )
    return result


def compare(
    dataset: Union[str, "os.PathLike[str]"],
    model: Optional[str] = None,
    *,
    schemes: Sequence[str] = ("ff100", "ff50", "ff25"),
    subset: Optional[int] = None,
    step: Optional[int] = None,
    prefilter_sigma: Optional[float] = None,
    seed: Optional[int] = None,
    history: bool = True,
    data_dir: str = "data",
) -> Dict[str, Any]:
    """A dataset folder against the model: the document of ``ffdic compare --json``.

    DIC runs on the measured frames and on the frames the model renders for the same nominal
    experiment; the discrepancy per run and scheme and in total (px). Recorded in the
    dataset's history unless ``history=False``: ``DATA_DIR/history/NAME-HASH/ffdic-history.jsonl``,
    where ``ffdic history`` finds it (nothing is written into the dataset's folder). ``schemes`` takes the
    names :func:`reduce` takes (``"native"`` for a camera's own resolution).
    """
    result: Dict[str, Any] = _ffdic.compare(
        dataset,
        model,
        schemes=list(schemes),
        subset=subset,
        step=step,
        prefilter_sigma=prefilter_sigma,
        seed=seed,
        history=history,
        data_dir=data_dir,
    )
    return result


def diagnose(
    dataset: Union[str, "os.PathLike[str]"],
    model: Optional[str] = None,
    *,
    rounds: int = 1,
    schemes: Sequence[str] = ("ff100", "ff50", "ff25"),
    subset: Optional[int] = None,
    step: Optional[int] = None,
    prefilter_sigma: Optional[float] = None,
    seed: Optional[int] = None,
    data_dir: str = "data",
) -> Dict[str, Any]:
    """Which physical effect the model misses: the document of ``ffdic diagnose --json``.

    Every candidate effect is fitted and ranked (verdict, ΔBIC, parameters with their
    uncertainty); with ``rounds`` > 1 the winner is added and the dataset diagnosed again.
    When a round found an effect, ``final_model_toml`` holds the model with every winner
    added (add it to a daemon with ``Client.add_model``).
    """
    result: Dict[str, Any] = _ffdic.diagnose(
        dataset,
        model,
        rounds=rounds,
        schemes=list(schemes),
        subset=subset,
        step=step,
        prefilter_sigma=prefilter_sigma,
        seed=seed,
        data_dir=data_dir,
    )
    return result

