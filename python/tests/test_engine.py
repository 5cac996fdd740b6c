"""The native module against the CLI and against independent arithmetic.

- `analyze` gives the numbers `ffdic analyze` writes for the same images (DIC Challenge Sample 3,
  a published benchmark: images no ffdic code made), bit for bit;
- a C-contiguous float32 array is read without a copy, and every other layout gives the same
  numbers;
- the GIL is released: two analyses in two Python threads run at the same time, and the main
  thread runs while one of them works;
- bad input raises ValueError with a message naming the problem;
- `reduce` against the fill-factor schemes written out in numpy (block means and subsampling);
- `render`, `compare` and `diagnose` against `ffdic simulate`, `ffdic compare --json` and
  `ffdic diagnose --json`.
"""

from __future__ import annotations

import csv
import json
import struct
import subprocess
import threading
import time
import zlib
from pathlib import Path
from typing import Any, Dict, List

import numpy as np
import pytest

import ffdic

from conftest import REPO, ffdic_binary

SAMPLE3 = REPO.parent / "shared" / "data" / "dic-challenge-1" / "sample3"
#: A small analysis of Sample 3: 11 x 11 points.
SMALL = {"subset": 41, "step": 40}


def cli(*args: str, timeout: float = 600) -> subprocess.CompletedProcess:
    done = subprocess.run(
        [str(ffdic_binary()), *args], capture_output=True, timeout=timeout, env={"RUST_LOG": "warn"}
    )
    assert done.returncode == 0, done.stderr.decode(errors="replace")
    return done


def read_points_csv(path: Path) -> Dict[str, np.ndarray]:
    with path.open() as f:
        rows = list(csv.DictReader(f))
    out: Dict[str, np.ndarray] = {}
    for name in rows[0]:
        if name == "status":
            out[name] = np.array([r[name] for r in rows])
        else:
            out[name] = np.array([float(r[name]) for r in rows])
    return out


def same(a: np.ndarray, b: np.ndarray) -> bool:
    """Equal values, NaN where the other has NaN."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    return a.shape == b.shape and bool(np.all((a == b) | (np.isnan(a) & np.isnan(b))))


@pytest.fixture(scope="module")
def sample3() -> Dict[str, np.ndarray]:
    if not SAMPLE3.is_dir():
        pytest.fail(f"DIC Challenge Sample 3 missing at {SAMPLE3}", pytrace=False)
    return {
        "reference": ffdic.read_image(SAMPLE3 / "reference.tif"),
        "shift_05": ffdic.read_image(SAMPLE3 / "shift_05.tif"),
    }


def test_analyze_equals_the_cli_on_sample3(tmp_path: Path, sample3: Dict[str, np.ndarray]) -> None:
    ref = SAMPLE3 / "reference.tif"
    deformed = SAMPLE3 / "shift_05.tif"
    out = tmp_path / "cli"
    done = cli("analyze", str(ref), str(deformed), "--subset", "31", "--step", "16", "--json", "--out", str(out))
    cli_doc = json.loads(done.stdout)
    points = read_points_csv(out / "points.csv")

    assert sample3["reference"].dtype == np.uint8 and sample3["reference"].shape == (512, 512)
    r = ffdic.analyze(sample3["reference"], sample3["shift_05"], subset=31, step=16)
    for name in ["x", "y", "u", "v", "exx", "eyy", "exy", "zncc", "u_std_px", "v_std_px", "iterations"]:
        assert same(getattr(r, name), points[name]), name
    assert list(r.status_names) == list(points["status"])
    # The summary is the CLI's document (its elapsed time and file names aside).
    summary = dict(r.summary)
    for key in ["points", "valid", "statuses", "u", "v", "exx", "eyy", "exy", "global_offset_px"]:
        assert json.dumps(summary[key], sort_keys=True) == json.dumps(cli_doc[key], sort_keys=True), key
    assert r.settings["dic"] == cli_doc["settings"]["dic"]
    assert r.strain_gauge_px == cli_doc["settings"]["strain_gauge_px"]
    assert r.grid_shape == (cli_doc["settings"]["grid"]["ny"], cli_doc["settings"]["grid"]["nx"])
    # Sample 3's shift_05 moves the content by (0.5, 0.5) px (the benchmark's own truth).
    valid = r.status == int(ffdic.Status.CONVERGED)
    assert valid.sum() > 0.9 * valid.size
    assert abs(np.mean(r.u[valid]) - 0.5) < 0.01 and abs(np.mean(r.v[valid]) - 0.5) < 0.01
    assert "<table>" in r._repr_html_() and "valid" in repr(r)


def test_float32_c_arrays_are_read_in_place_and_every_layout_agrees(sample3: Dict[str, np.ndarray]) -> None:
    ref8, def8 = sample3["reference"], sample3["shift_05"]
    ref32 = np.ascontiguousarray(ref8, dtype=np.float32)
    def32 = np.ascontiguousarray(def8, dtype=np.float32)
    base = ffdic.analyze(ref32, def32, **SMALL)
    assert (base.reference_copied, base.deformed_copied) == (False, False)

    # A strided view of a larger C array (every other column of a doubled image) is not
    # contiguous: copied, same numbers.
    wide = np.zeros((512, 1024), dtype=np.float32)
    wide[:, ::2] = ref32
    layouts = {
        "uint8": (ref8, def8),
        "uint16": (ref8.astype(np.uint16), def8.astype(np.uint16)),
        "float64": (ref8.astype(np.float64), def8.astype(np.float64)),
        "fortran": (np.asfortranarray(ref32), np.asfortranarray(def32)),
        "strided": (wide[:, ::2], def32),
    }
    for name, (a, b) in layouts.items():
        r = ffdic.analyze(a, b, **SMALL)
        assert r.reference_copied, name
        for field in ["u", "v", "exx", "zncc"]:
            assert same(getattr(r, field), getattr(base, field)), (name, field)
    # A transposed (F-ordered) pair is the same image, not its transpose: same u, not u<->v.
    assert np.nanmean(base.u) > 0.4


def write_png_gray8(path: Path, image: np.ndarray) -> None:
    """An 8-bit grey PNG written with the standard library (zlib), no ffdic code."""
    height, width = image.shape
    raw = b"".join(b"\x00" + row.tobytes() for row in image.astype(np.uint8))

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    header = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", zlib.compress(raw))
                     + chunk(b"IEND", b""))


def test_a_mask_equals_the_cli_mask(tmp_path: Path, sample3: Dict[str, np.ndarray]) -> None:
    mask = np.ones((512, 512), dtype=bool)
    mask[:, :256] = False  # the left half is not analysed
    mask[400:, 300:] = False
    write_png_gray8(tmp_path / "mask.png", mask * 255)
    out = tmp_path / "cli"
    cli("analyze", str(SAMPLE3 / "reference.tif"), str(SAMPLE3 / "shift_05.tif"), "--subset", "31",
        "--step", "16", "--mask", str(tmp_path / "mask.png"), "--out", str(out))
    points = read_points_csv(out / "points.csv")
    r = ffdic.analyze(sample3["reference"], sample3["shift_05"], subset=31, step=16, mask=mask)
    for name in ["x", "y", "u", "v", "exx", "zncc"]:
        assert same(getattr(r, name), points[name]), name
    names = np.array(r.status_names)
    assert list(names) == list(points["status"])
    # Every point whose centre lies on a masked pixel is masked, and only those.
    on_mask = ~mask[r.y.astype(int), r.x.astype(int)]
    assert on_mask.sum() > 0 and np.all(names[on_mask] == "masked")
    assert not np.any(names[~on_mask] == "masked")
    with pytest.raises(ValueError, match="differ in shape"):
        ffdic.analyze(sample3["reference"], sample3["shift_05"], mask=mask[:, :500])
    with pytest.raises(ValueError, match="one image pair"):
        ffdic.analyze(sample3["reference"], [sample3["shift_05"]], mask=mask)


def test_a_sequence_equals_the_cli_sequence(tmp_path: Path) -> None:
    names = [f"shift_{k:02d}.tif" for k in (1, 3, 6, 10)]
    out = tmp_path / "cli"
    cli("analyze", str(SAMPLE3 / "reference.tif"), *[str(SAMPLE3 / n) for n in names],
        "--subset", "41", "--step", "40", "--out", str(out))
    frames = [ffdic.read_image(SAMPLE3 / n) for n in names]
    results = ffdic.analyze(ffdic.read_image(SAMPLE3 / "reference.tif"), frames, **SMALL)
    assert isinstance(results, list) and len(results) == len(names)
    doc = json.loads((out / "settings.json").read_text())
    for k, (r, frame_doc) in enumerate(zip(results, doc["frames"])):
        points = read_points_csv(out / f"points_{k + 1:04d}.csv")
        for name in ["x", "y", "u", "v", "exx"]:
            assert same(getattr(r, name), points[name]), (k, name)
        assert r.reference_index == frame_doc["reference_index"]
    # Sample 3's truth: shift_k moved by 0.1·k px in x and y.
    for r, k in zip(results, (1, 3, 6, 10)):
        valid = r.status == int(ffdic.Status.CONVERGED)
        assert abs(np.mean(r.u[valid]) - 0.1 * k) < 0.01 and abs(np.mean(r.v[valid]) - 0.1 * k) < 0.01


def test_dataset_init_writes_the_manifest_the_cli_writes(tmp_path: Path) -> None:
    by_python, by_cli = tmp_path / "python", tmp_path / "cli"
    for folder in (by_python, by_cli):
        folder.mkdir()
        for f in ["reference.tif", "shift_00.tif", "shift_01.tif", "shift_02.tif", "shift_03.tif"]:
            (folder / f).write_bytes((SAMPLE3 / f).read_bytes())
    manifest = ffdic.dataset_init(by_python, scale_px_per_mm=10.0, step_px=(0.1, 0.1),
                                  repeats=["shift_00.tif"], name="s3", stage_repeatability_um=2.0)
    cli("dataset", "init", str(by_cli), "--scale", "10", "--step-px", "0.1,0.1", "--repeat",
        "shift_00.tif", "--name", "s3", "--stage-repeatability-um", "2")
    assert json.loads((by_python / "dataset.json").read_text()) == json.loads((by_cli / "dataset.json").read_text())
    assert manifest == json.loads((by_python / "dataset.json").read_text())
    assert [r["deformed"] for r in manifest["runs"]] == ["shift_01.tif", "shift_02.tif", "shift_03.tif"]
    assert manifest["runs"][2]["stage"]["dx_mm"] == pytest.approx(0.03)
    # Once: an existing manifest stays unless force=True; every problem is named at once.
    with pytest.raises(ValueError, match="force=True"):
        ffdic.dataset_init(by_python, scale_px_per_mm=10.0, step_px=(0.1, 0.1))
    with pytest.raises(ValueError) as problems:
        ffdic.dataset_init(by_python, scale_px_per_mm=10.0, step_mm=(0.0, 0.0), force=True,
                           reference="missing.tif", repeats=["gone.tif"])
    for part in ["missing.tif", "gone.tif", "not zero"]:
        assert part in str(problems.value), str(problems.value)
    with pytest.raises(ValueError, match="not both"):
        ffdic.dataset_init(by_python, scale_px_per_mm=10.0, step_mm=(1, 0), step_px=(1, 0), force=True)


def test_the_gil_is_released(sample3: Dict[str, np.ndarray]) -> None:
    """Each call records when it ran (inside its thread, with the GIL held just before and
    after). Holding the GIL through the call, a second call could not begin before the first
    ended, and the main thread could not run in between."""
    big_ref = np.ascontiguousarray(np.tile(sample3["reference"], (2, 2)), dtype=np.float32)
    big_def = np.ascontiguousarray(np.tile(sample3["shift_05"], (2, 2)), dtype=np.float32)
    spans: List[List[float]] = []

    def work() -> None:
        start = time.perf_counter()
        ffdic.analyze(big_ref, big_def, subset=21, step=4, roi=(0, 0, 1024, 1024), threads=1)
        spans.append([start, time.perf_counter()])

    threads = [threading.Thread(target=work) for _ in range(2)]
    ticks: List[float] = []
    for t in threads:
        t.start()
    while any(t.is_alive() for t in threads):
        ticks.append(time.perf_counter())
        time.sleep(0.001)
    for t in threads:
        t.join()
    (a0, a1), (b0, b1) = sorted(spans)
    assert b0 < a1, f"the second call began {b0 - a1:.3f} s after the first ended"
    during = [t for t in ticks if a0 < t < a1]
    assert len(during) > 0, "the main thread never ran during an analysis"


@pytest.mark.parametrize(
    "reference, deformed, message",
    [
        (np.zeros((8, 8, 3), np.uint8), np.zeros((8, 8, 3), np.uint8), "2-D"),
        (np.zeros((64, 64), np.float32), np.zeros((64, 60), np.float32), "differ in shape"),
        (np.full((64, 64), np.nan, np.float32), np.zeros((64, 64), np.float32), "NaN or infinite (all of them)"),
        (np.zeros((64, 64), np.int32), np.zeros((64, 64), np.int32), "dtype int32 is not supported"),
        (np.zeros((64, 64), np.complex64), np.zeros((64, 64), np.complex64), "is not supported"),
        ([[1.0, 2.0]], [[1.0, 2.0]], "expected a 2-D numpy array, got list"),
        (np.zeros((0, 64), np.float32), np.zeros((0, 64), np.float32), "empty"),
    ],
)
def test_bad_input_raises_a_clear_value_error(reference: Any, deformed: Any, message: str) -> None:
    with pytest.raises(ValueError, match=message.replace("(", r"\(").replace(")", r"\)")):
        ffdic.analyze(reference, deformed)


def test_bad_settings_name_their_keyword(sample3: Dict[str, np.ndarray]) -> None:
    ref, deformed = sample3["reference"], sample3["shift_05"]
    for kwargs, message in [
        ({"subset": 40}, "subset"),
        ({"interp": "cubic"}, "interp"),
        ({"shape": "cubic"}, "shape"),
        ({"threads": 0}, "threads"),
        ({"roi": (600, 600, 10, 10)}, "ROI"),
    ]:
        with pytest.raises(ValueError, match=message):
            ffdic.analyze(ref, deformed, **kwargs)


def test_reduce_matches_the_schemes_written_in_numpy() -> None:
    rng = np.random.default_rng(7)
    frame = rng.integers(0, 4096, size=(64, 96)).astype(np.uint16)
    f = frame.astype(np.float64)
    # ff100: 2x2 binning (mean of the block); ff50: rows binned (mean of the two rows of a
    # block), the first column of every pair; ff25: the top-left pixel of every 2x2 block.
    expected = {
        "ff100": f.reshape(32, 2, 48, 2).mean(axis=(1, 3)),
        "ff50": f.reshape(32, 2, 48, 2).mean(axis=1)[:, :, 0],
        "ff25": f[::2, ::2],
        "native": f,
        # 3x3 blocks, the centred pixel of each.
        "3x3/1x1": f[:63, :96].reshape(21, 3, 32, 3)[:, 1, :, 1],
    }
    for name, want in expected.items():
        got = ffdic.reduce(frame, name)
        assert got.dtype == np.float32 and got.shape == want.shape, name
        assert np.allclose(got, want, rtol=0, atol=1e-3), name
    # A scheme per axis: 3-pixel blocks, the middle pixel in x, all three rows in y.
    got = ffdic.reduce(frame[:63, :96], "mid", x=(3, 1, 1), y=(3, 0, 3))
    want = f[:63, :96].reshape(21, 3, 32, 3).mean(axis=1)[:, :, 1]
    assert np.allclose(got, want, atol=1e-3)
    with pytest.raises(ValueError, match="scheme"):
        ffdic.reduce(frame, "ff33")
    with pytest.raises(ValueError, match="scheme"):
        ffdic.reduce(frame, "bad", x=(2, 1, 2), y=(2, 0, 1))


EXPERIMENT = """\
name = "python-render"
seed = 11
patterns = ["a"]
static_frames = 0
schemes = ["ff100"]

[camera]
width = 256
height = 192
scale_px_per_mm = 13.0
exposure_level = 0.5

[[moves]]
id = "x1"
dx_mm = 1.0
dy_mm = 0.0
"""


def test_render_gives_the_frames_ffdic_simulate_writes(tmp_path: Path) -> None:
    rendered = ffdic.render(EXPERIMENT, "paper-bench", seed=3)
    (tmp_path / "e.toml").write_text(EXPERIMENT)
    cli("simulate", "--experiment", str(tmp_path / "e.toml"), "--seed", "3", "--out", str(tmp_path / "d"))
    manifest = json.loads((tmp_path / "d" / "dataset.json").read_text())
    assert rendered["manifest"]["runs"] == manifest["runs"]
    assert len(rendered["frames"]) == 2
    for name, frame in rendered["frames"].items():
        assert frame.dtype == np.uint16 and frame.shape == (192, 256)
        assert np.array_equal(frame, ffdic.read_image(tmp_path / "d" / name)), name
        assert np.array_equal(frame, ffdic.decode_tiff((tmp_path / "d" / name).read_bytes())), name


def test_compare_and_diagnose_equal_the_cli(simulated_dataset: Path, tmp_path: Path) -> None:
    """The documents of `ffdic compare --json` and `ffdic diagnose --json` on a dataset
    `ffdic simulate` made with a hidden lens distortion (conftest)."""
    cmp = ffdic.compare(simulated_dataset, "baseline", schemes=["ff100"], history=False)
    done = cli("compare", str(simulated_dataset), "--json", "--no-history", "--schemes", "ff100")
    assert json.dumps(cmp, sort_keys=True) == json.dumps(json.loads(done.stdout), sort_keys=True)
    assert cmp["discrepancy_px"] > 0

    diag = ffdic.diagnose(simulated_dataset, schemes=["ff100"])
    done = cli("diagnose", str(simulated_dataset), "--json", "--schemes", "ff100")
    cli_diag = json.loads(done.stdout)
    final_toml = diag.pop("final_model_toml", None)
    assert json.dumps(diag, sort_keys=True) == json.dumps(cli_diag, sort_keys=True)
    if diag.get("verdict") not in (None, "none"):
        assert final_toml is not None and "[effects" in final_toml

    # The history goes into the data folder, one folder per dataset; nothing into the dataset.
    data = tmp_path / "data"
    ffdic.compare(simulated_dataset, schemes=["ff100"], data_dir=str(data))
    (history,) = (data / "history").glob("*/ffdic-history.jsonl")
    assert len(history.read_text().splitlines()) == 1
    assert not (simulated_dataset / "ffdic-history.jsonl").exists()
    with pytest.raises(ValueError, match="not a dataset folder"):
        ffdic.compare(tmp_path)
    with pytest.raises(ValueError, match="no such file"):
        ffdic.compare(simulated_dataset, "no-such-model")
    with pytest.raises(ValueError, match="rounds"):
        ffdic.diagnose(simulated_dataset, rounds=0)


def test_version_and_statuses() -> None:
    assert ffdic.__version__ == cli("--version").stdout.decode().split()[-1]
    assert ffdic.Status(0).name == "CONVERGED"


def test_the_namespace_offers_the_api_not_its_imports() -> None:
    names = dir(ffdic)
    for private in ("Any", "np", "os", "json", "enum"):
        assert private not in names, f"{private} in dir(ffdic)"
    for public in ffdic.__all__:
        assert public in names and hasattr(ffdic, public), public
