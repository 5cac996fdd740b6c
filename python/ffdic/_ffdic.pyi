"""Type stubs of the native module `ffdic._ffdic` (python/src/*.rs). Use it through `ffdic`."""

from os import PathLike
from typing import Any, Dict, List, Optional, Tuple, Union

import numpy as np
import numpy.typing as npt

__version__: str
#: Status names by code: `AnalysisResult.status` holds indices into this list.
STATUSES: List[str]

class AnalysisResult:
    """One analysis: per-point arrays, row-major over a grid of `grid_shape` points."""

    #: Subset centres in the reference image, px.
    x: npt.NDArray[np.float64]
    y: npt.NDArray[np.float64]
    #: Displacements, px (NaN where the point is not converged).
    u: npt.NDArray[np.float64]
    v: npt.NDArray[np.float64]
    #: Small strains from the strain window.
    exx: npt.NDArray[np.float64]
    eyy: npt.NDArray[np.float64]
    exy: npt.NDArray[np.float64]
    #: Zero-normalised cross-correlation at the solution.
    zncc: npt.NDArray[np.float64]
    #: Predicted standard deviation of u and v from the fit residual, px.
    u_std_px: npt.NDArray[np.float64]
    v_std_px: npt.NDArray[np.float64]
    iterations: npt.NDArray[np.uint32]
    #: Status codes (see `ffdic.Status`; 0 = converged).
    status: npt.NDArray[np.uint8]
    #: Status names per point.
    status_names: List[str]
    #: (rows, columns) of the point grid.
    grid_shape: Tuple[int, int]
    #: ROI holding the point centres: (x, y, width, height), px.
    roi: Tuple[int, int, int, int]
    #: Size of the virtual strain gauge, px.
    strain_gauge_px: int
    #: Integer rigid offset of the global FFT cross-correlation, px.
    global_offset_px: Tuple[int, int]
    #: Every setting, as `ffdic analyze --out` writes settings.json.
    settings: Dict[str, Any]
    #: The document `ffdic analyze --json` prints (points, valid, statuses, u, v, strains…).
    summary: Dict[str, Any]
    #: Wall time of the analysis, s.
    elapsed_s: float
    #: Whether the images were copied out of their arrays (False for C-contiguous float32).
    reference_copied: bool
    deformed_copied: bool
    #: In a sequence, the frame this one was correlated against (0: the reference given).
    reference_index: int
    def _repr_html_(self) -> str: ...

def analyze(
    reference: npt.ArrayLike,
    deformed: Union[npt.ArrayLike, List[npt.ArrayLike]],
    *,
    subset: Optional[int] = None,
    step: Optional[int] = None,
    roi: Optional[Tuple[int, int, int, int]] = None,
    strain_window: Optional[int] = None,
    interp: Optional[str] = None,
    shape: Optional[str] = None,
    prefilter_sigma: Optional[float] = None,
    min_zncc: Optional[float] = None,
    max_motion: Optional[int] = None,
    max_displacement_std: Optional[float] = None,
    outlier_threshold: Optional[float] = None,
    outlier_test: bool = True,
    mask: Optional[npt.ArrayLike] = None,
    threads: Optional[int] = None,
) -> Union[AnalysisResult, List[AnalysisResult]]: ...
def reduce(frame: npt.ArrayLike, scheme_json: str = "ff50") -> npt.NDArray[np.float32]: ...
def decode_tiff(data: bytes) -> npt.NDArray[Any]: ...
def read_image(path: Union[str, PathLike[str]]) -> npt.NDArray[Any]: ...
def render(
    experiment: Optional[str] = None,
    model: Optional[str] = None,
    seed: Optional[int] = None,
    data_dir: str = "data",
) -> Dict[str, Any]: ...
def dataset_init(
    folder: Union[str, PathLike[str]],
    *,
    scale_px_per_mm: float,
    step_mm: Optional[Tuple[float, float]] = None,
    step_px: Optional[Tuple[float, float]] = None,
    reference: Optional[str] = None,
    repeats: List[str] = ...,
    name: Optional[str] = None,
    pattern: Optional[str] = None,
    stage_repeatability_um: Optional[float] = None,
    force: bool = False,
) -> Dict[str, Any]: ...
def compare(
    dataset: Union[str, PathLike[str]],
    model: Optional[str] = None,
    *,
    schemes: List[str] = ...,
    subset: Optional[int] = None,
    step: Optional[int] = None,
    prefilter_sigma: Optional[float] = None,
    seed: Optional[int] = None,
    history: bool = True,
    data_dir: str = "data",
) -> Dict[str, Any]: ...
def diagnose(
    dataset: Union[str, PathLike[str]],
    model: Optional[str] = None,
    *,
    rounds: int = 1,
    schemes: List[str] = ...,
    subset: Optional[int] = None,
    step: Optional[int] = None,
    prefilter_sigma: Optional[float] = None,
    seed: Optional[int] = None,
    data_dir: str = "data",
) -> Dict[str, Any]: ...
