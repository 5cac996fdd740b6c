"""Speed of `ffdic.analyze` from Python against `ffdic analyze` (the CLI), measured in one run,
interleaved (the machine is shared: compare ratios, not absolute times).

    python python/benchmarks/speed_vs_cli.py [--rounds 15] [--step 5]

1. A 1280x1080 reference/deformed pair (pattern a, a 1 mm move) rendered by `ffdic simulate`
   from the paper-bench model, written as 16-bit TIFFs.
2. `rounds` times, alternating: the CLI on the two files (`--step STEP --json`; its `elapsed_s`
   covers preparing the reference and correlating, read from its JSON) and `ffdic.analyze` on
   the same frames as float32 arrays (its `elapsed_s` covers the same work; the call's wall
   time adds the array conversion and the result's arrays). Both use every core.
3. The overhead of one Python call on a 512x512 pair (DIC Challenge Sample 3, subset 41,
   step 20): wall time of the call minus the engine's own `elapsed_s`, median of 20 calls.

The CLI is `FFDIC_BIN`, else target/release/ffdic. Build both in release first:
`cargo build --release --bin ffdic` and `pip install ./python`.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import tempfile
import time
from pathlib import Path
from typing import List

import numpy as np

import ffdic

REPO = Path(__file__).resolve().parents[2]
SAMPLE3 = REPO.parent / "shared" / "data" / "dic-challenge-1" / "sample3"

EXPERIMENT = """\
name = "speed"
seed = 1
patterns = ["a"]
static_frames = 0
schemes = ["ff100"]

[camera]
width = 1280
height = 1080
scale_px_per_mm = 26.0
exposure_level = 0.5

[[moves]]
id = "x1"
dx_mm = 1.0
dy_mm = 0.0
"""


def cli_binary() -> Path:
    path = Path(os.environ.get("FFDIC_BIN") or REPO / "target" / "release" / "ffdic")
    if not path.is_file():
        raise SystemExit(f"no CLI at {path}: cargo build --release --bin ffdic, or set FFDIC_BIN")
    return path


def t_975(dof: int) -> float:
    """The 97.5 % quantile of Student's t (two-sided 95 % intervals), tabulated to dof 30."""
    table = [12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228, 2.201, 2.179,
             2.160, 2.145, 2.131, 2.120, 2.110, 2.101, 2.093, 2.086, 2.080, 2.074, 2.069, 2.064,
             2.060, 2.056, 2.052, 2.048, 2.045, 2.042]
    return table[dof - 1] if 1 <= dof <= len(table) else 1.96


def spread(values: List[float]) -> str:
    return f"median {statistics.median(values):.3f} (min {min(values):.3f}, max {max(values):.3f})"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--rounds", type=int, default=15)
    parser.add_argument("--step", type=int, default=5)
    args = parser.parse_args()
    binary = cli_binary()
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        (work / "e.toml").write_text(EXPERIMENT)
        subprocess.run(
            [str(binary), "simulate", "--experiment", str(work / "e.toml"), "--out", str(work / "d")],
            check=True,
            capture_output=True,
        )
        run = json.loads((work / "d" / "dataset.json").read_text())["runs"][0]
        ref_path, def_path = work / "d" / run["reference"], work / "d" / run["deformed"]
        reference = np.ascontiguousarray(ffdic.read_image(ref_path), dtype=np.float32)
        deformed = np.ascontiguousarray(ffdic.read_image(def_path), dtype=np.float32)
        print(f"pair {reference.shape[1]}x{reference.shape[0]}, step {args.step} px, subset 41 px, every core")

        cli_s: List[float] = []
        py_s: List[float] = []
        py_wall_s: List[float] = []
        ratios: List[float] = []
        for k in range(args.rounds):
            done = subprocess.run(
                [str(binary), "analyze", str(ref_path), str(def_path), "--step", str(args.step), "--json"],
                check=True,
                capture_output=True,
            )
            cli_s.append(json.loads(done.stdout)["elapsed_s"])
            started = time.perf_counter()
            result = ffdic.analyze(reference, deformed, step=args.step)
            py_wall_s.append(time.perf_counter() - started)
            py_s.append(result.elapsed_s)
            ratios.append(py_wall_s[-1] / cli_s[-1])
            print(
                f"  round {k + 1}: CLI {cli_s[-1]:.3f} s, Python {py_s[-1]:.3f} s "
                f"(call {py_wall_s[-1]:.3f} s), {result.summary['points']} points"
            )
        print(f"CLI elapsed_s:           {spread(cli_s)} s")
        print(f"Python elapsed_s:        {spread(py_s)} s")
        print(f"Python call (wall):      {spread(py_wall_s)} s")
        print(f"Python call / CLI, per round: {spread(ratios)}")
        logs = np.log(ratios)
        half = t_975(len(logs) - 1) * float(np.std(logs, ddof=1)) / np.sqrt(len(logs))
        mean = float(np.mean(logs))
        print(
            f"Python call / CLI, geometric mean over rounds: {np.exp(mean):.3f} "
            f"(95 % interval {np.exp(mean - half):.3f} to {np.exp(mean + half):.3f}, Student t)"
        )

    ref8 = ffdic.read_image(SAMPLE3 / "reference.tif")
    def8 = ffdic.read_image(SAMPLE3 / "shift_05.tif")
    overhead_ms: List[float] = []
    engine_ms: List[float] = []
    for _ in range(20):
        started = time.perf_counter()
        r = ffdic.analyze(ref8, def8)
        wall = time.perf_counter() - started
        overhead_ms.append((wall - r.elapsed_s) * 1e3)
        engine_ms.append(r.elapsed_s * 1e3)
    print(
        f"512x512 pair (uint8, subset 41, step 20, {r.summary['points']} points): engine "
        f"{statistics.median(engine_ms):.2f} ms, overhead of the call {spread(overhead_ms)} ms"
    )


if __name__ == "__main__":
    main()
