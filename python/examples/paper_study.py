"""The paper's fill-factor study from Python, end to end, on the mock bench.

    python python/examples/paper_study.py              # starts `ffdic serve` itself
    python python/examples/paper_study.py --url http://127.0.0.1:8080 [--token T]

Steps (each printed with what it shows):
  1. run the paper's experiment (patterns a, b, c; a 5 mm move; fill factors 100, 50, 25 %)
     and follow its progress;
  2. print the displacement-error table: std of u and v per pattern and scheme;
  3. draw Figure 5 of the paper (std of u per pattern and fill factor) into figure5.png, if
     matplotlib is installed;
  4. upload a dataset `ffdic simulate` made on a bench with a lens distortion, compare it with
     the baseline model, diagnose what the model lacks, add the winning effect as a new model
     version, compare again, and print the dataset's history: the discrepancy falls.

Without --url the script needs the ffdic binary: FFDIC_BIN, else `ffdic` on PATH, else
target/release/ffdic, then target/debug/ffdic of this repository. It serves a small mock bench
(400x320 px at 13 px/mm) from a temporary data folder and stops it at the end.
"""

from __future__ import annotations

import argparse
import math
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any, Dict, List, Optional

HERE = Path(__file__).resolve().parent
REPO = HERE.parents[1]

try:
    from ffdic import Client, ProblemError
except ImportError:
    # Run from a checkout without the package installed (or without its native module built):
    # the client itself is plain Python.
    sys.path.insert(0, str(REPO / "python"))
    try:
        from ffdic.client import Client, ProblemError
    except ImportError:
        import importlib.util

        spec = importlib.util.spec_from_file_location("ffdic.client", REPO / "python" / "ffdic" / "client.py")
        assert spec is not None and spec.loader is not None
        module = importlib.util.module_from_spec(spec)
        sys.modules["ffdic.client"] = module
        spec.loader.exec_module(module)
        Client, ProblemError = module.Client, module.ProblemError  # type: ignore[misc]

#: The dataset step 4 uploads: one pattern, a static repeat and moves of several sizes and
#: directions (what tells a lens distortion from a rotation or a scale change).
EXPERIMENT_TOML = """\
name = "hidden-lens"
seed = 11
patterns = ["a"]
static_frames = 1
schemes = ["ff100"]

[camera]
width = 512
height = 512
scale_px_per_mm = 13.0
exposure_level = 0.5

[[moves]]
id = "x2"
dx_mm = 2.0
dy_mm = 0.0

[[moves]]
id = "x4"
dx_mm = 4.0
dy_mm = 0.0

[[moves]]
id = "y3"
dx_mm = 0.0
dy_mm = 3.0
"""

#: ... rendered on a bench whose lens distorts; the baseline model does not know that.
BENCH_TOML = """\
name = "bench-hidden-lens"
description = "a bench whose lens distorts (k1 = -0.003), which the baseline model lacks"

[effects.stage_misalignment]
angle_rad = 0.004

[effects.lens_distortion]
k1 = -0.003

[effects.sensor_noise]
full_well_e = 1e10
read_noise_e = 1.5e6
gain = 1e4
"""

#: Native resolution and small subsets for the model comparisons: quick on two cores.
NATIVE = {"name": "native", "x": {"block": 1, "first": 0, "active": 1}, "y": {"block": 1, "first": 0, "active": 1}}
SMALL_DIC = {"subset_px": 21, "step_px": 10, "strain_window": 5}


def step(title: str, text: str) -> None:
    print(f"\n== {title}\n   {text}", flush=True)


def find_binary() -> Optional[Path]:
    """FFDIC_BIN, else `ffdic` on PATH, else this repository's release then debug build."""
    if os.environ.get("FFDIC_BIN"):
        return Path(os.environ["FFDIC_BIN"])
    on_path = shutil.which("ffdic")
    if on_path:
        return Path(on_path)
    for build in ("release", "debug"):
        candidate = REPO / "target" / build / "ffdic"
        if candidate.is_file() and os.access(candidate, os.X_OK):
            return candidate
    return None


class LocalDaemon:
    """`ffdic serve` on 127.0.0.1 (a free port) with the small mock bench, in `workdir`."""

    def __init__(self, binary: Path, workdir: Path) -> None:
        self.binary = binary
        self.workdir = workdir
        self.proc: Optional[subprocess.Popen[bytes]] = None

    def start(self) -> str:
        config = self.workdir / "ffdic.toml"
        config.write_text(
            f'data_dir = "{(self.workdir / "data").as_posix()}"\n'
            'listen = "127.0.0.1:0"\n'
            "[bench]\nscale_px_per_mm = 13.0\n"
            '[camera]\nkind = "mock"\nwidth = 400\nheight = 320\n'
            '[stage]\nkind = "mock"\nspeed_mm_s = 25.0\nsettle_ms = 10\n'
        )
        env = dict(os.environ, NO_COLOR="1")
        env.pop("FFDIC_TOKEN", None)
        env.setdefault("RUST_LOG", "warn")
        out_path, log_path = self.workdir / "daemon.stdout", self.workdir / "daemon.log"
        with open(out_path, "wb") as out, open(log_path, "wb") as log:
            self.proc = subprocess.Popen(
                [str(self.binary), "serve", "--config", str(config)],
                stdout=out, stderr=log, stdin=subprocess.DEVNULL, env=env,
            )
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline:
            lines = out_path.read_text(errors="replace").split("\n", 1)
            if len(lines) == 2 and lines[0].startswith("listening on "):
                return lines[0][len("listening on "):].strip()
            if self.proc.poll() is not None:
                break
            time.sleep(0.05)
        self.stop()
        raise RuntimeError(f"`ffdic serve` did not start:\n{log_path.read_text(errors='replace')[-2000:]}")

    def stop(self) -> None:
        if self.proc is None or self.proc.poll() is not None:
            return
        self.proc.send_signal(signal.SIGTERM)  # the daemon stops within 10 s
        try:
            self.proc.wait(timeout=15)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()


def fmt_interval(lo: float, hi: float) -> str:
    if math.isnan(lo) or math.isnan(hi):
        return ""
    return f" [{lo:.4f}, {hi:.4f}]"


def print_error_table(table: Dict[str, Any]) -> None:
    has_intervals = not all(math.isnan(x) for x in table["u_std_lo"])
    print(f"   {'pattern':<8}{'scheme':<8}{'fill x,y':<10}{'std u (px)':<{30 if has_intervals else 12}}std v (px)")
    for i in range(len(table["run"])):
        fill = f"{table['fill_x'][i]:.2f},{table['fill_y'][i]:.2f}"
        u = f"{table['u_std'][i]:.4f}{fmt_interval(table['u_std_lo'][i], table['u_std_hi'][i])}"
        v = f"{table['v_std'][i]:.4f}{fmt_interval(table['v_std_lo'][i], table['v_std_hi'][i])}"
        print(f"   {table['pattern'][i]:<8}{table['scheme'][i]:<8}{fill:<10}{u:<{30 if has_intervals else 12}}{v}")
    if not has_intervals:
        print("   (one capture per pair, so no intervals: start_experiment(repeats=5) gives 95 % intervals)")


def draw_figure5(table: Dict[str, Any], path: Path) -> bool:
    """Figure 5: std of u per pattern (groups) and fill factor (bars). False without matplotlib."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return False
    import numpy as np

    patterns = sorted(set(table["pattern"].tolist()))
    schemes: List[str] = list(dict.fromkeys(table["scheme"].tolist()))
    width = 0.8 / len(schemes)
    fig, ax = plt.subplots(figsize=(6, 4))
    for k, scheme in enumerate(schemes):
        heights, lows, highs, fill = [], [], [], 1.0
        for p in patterns:
            i = int(np.flatnonzero((table["pattern"] == p) & (table["scheme"] == scheme))[0])
            heights.append(table["u_std"][i])
            lows.append(table["u_std"][i] - table["u_std_lo"][i])
            highs.append(table["u_std_hi"][i] - table["u_std"][i])
            fill = table["fill_x"][i] * table["fill_y"][i]
        err = None if all(math.isnan(x) for x in lows) else [lows, highs]
        ax.bar(np.arange(len(patterns)) + (k - (len(schemes) - 1) / 2) * width, heights, width,
               yerr=err, capsize=3, label=f"{scheme} (fill factor {100 * fill:.0f} %)")
    ax.set_xticks(np.arange(len(patterns)))
    ax.set_xticklabels([f"pattern {p}" for p in patterns])
    ax.set_ylabel("std of u (px)")
    ax.set_title("Figure 5: displacement error against fill factor")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return True


def simulate_dataset(binary: Path, workdir: Path) -> Path:
    (workdir / "experiment.toml").write_text(EXPERIMENT_TOML)
    (workdir / "bench.toml").write_text(BENCH_TOML)
    out = workdir / "hidden-lens"
    subprocess.run(
        [str(binary), "simulate", "--experiment", str(workdir / "experiment.toml"),
         "--model", str(workdir / "bench.toml"), "--out", str(out), "--force"],
        check=True, capture_output=True, env=dict(os.environ, RUST_LOG="warn", NO_COLOR="1"),
    )
    return out


def add_winner(client: Client, toml_text: str) -> Dict[str, Any]:
    """Stores the diagnosis's winner; under a name already holding another model, renames it."""
    try:
        return client.add_model(toml_text)
    except ProblemError as e:
        if e.status != 409:
            raise
        lines = toml_text.splitlines()
        for i, line in enumerate(lines):
            if line.startswith("name ="):
                lines[i] = line.rstrip().rstrip('"') + f'-{time.strftime("%Y%m%d%H%M%S")}"'
                break
        return client.add_model("\n".join(lines) + "\n")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--url", help="a running daemon (default: start one on the mock bench)")
    ap.add_argument("--token", default=os.environ.get("FFDIC_TOKEN"), help="its token (default: FFDIC_TOKEN)")
    ap.add_argument("--out", type=Path, default=Path("."), help="folder for figure5.png (default: .)")
    args = ap.parse_args()

    binary = find_binary()
    work = Path(tempfile.mkdtemp(prefix="ffdic-paper-study-"))
    daemon: Optional[LocalDaemon] = None
    try:
        url = args.url
        if url is None:
            if binary is None:
                print("no ffdic binary: set FFDIC_BIN, put `ffdic` on PATH, or `cargo build --release`",
                      file=sys.stderr)
                return 2
            daemon = LocalDaemon(binary, work)
            url = daemon.start()
            step("A daemon on the mock bench",
                 f"{binary} serve, listening on {url}, data in {work / 'data'} (removed at the end).")
        client = Client(url, token=args.token, timeout_s=60)
        health = client.health()
        camera = client.camera()["info"]
        print(f"   ffdic {health['version']}: {health['status']}; camera {camera['model']} "
              f"{camera['sensor_width']}x{camera['sensor_height']} px")

        # 1 -------------------------------------------------------------------------------------
        step("1. The paper's experiment",
             "start_experiment() with no fields: patterns a, b, c, one 5 mm move along x, each pair "
             "reduced to fill factors 100, 50 and 25 % and correlated. follow() prints the progress.")
        run = client.start_experiment()
        t0 = time.monotonic()
        record = client.follow(run, progress=True)
        print(f"   {run}: {record['status']} in {time.monotonic() - t0:.1f} s - {record['message']}")

        # 2 -------------------------------------------------------------------------------------
        step("2. Displacement error per pattern and scheme",
             "results_table() reads results.csv into numpy columns. The move is a rigid translation, so "
             "the spread (std) of u and v over the DIC grid is the measurement error, in pixels of the "
             "reduced image. The paper's finding: it grows as the fill factor falls.")
        table = client.results_table(run)
        print_error_table(table)

        # 3 -------------------------------------------------------------------------------------
        step("3. Figure 5", "std of u per pattern and fill factor, as a bar chart.")
        args.out.mkdir(parents=True, exist_ok=True)
        figure = args.out / "figure5.png"
        if draw_figure5(table, figure):
            print(f"   wrote {figure.resolve()}")
        else:
            print("   matplotlib is not installed: no figure5.png (pip install matplotlib). The daemon's own "
                  f"SVG is {url}/api/v1/experiments/{run}/plots/figure5_u.svg")

        # 4 -------------------------------------------------------------------------------------
        step("4. A model against a measurement",
             "The experiment's frames are a dataset already "
             f"({record.get('dataset_id')}). To see a diagnosis find something, upload frames "
             "`ffdic simulate` renders on a bench whose lens distorts - an effect the baseline model lacks.")
        if binary is not None:
            dataset_id = client.upload_dataset(simulate_dataset(binary, work))
            print(f"   uploaded dataset {dataset_id}: {client.dataset(dataset_id)['runs']} runs")
        else:
            dataset_id = record["dataset_id"]
            print(f"   no ffdic binary here to simulate with: using the experiment's dataset {dataset_id}")

        before = client.compare(dataset_id, model="baseline", schemes=[NATIVE], dic=SMALL_DIC)
        print(f"   compare with baseline: discrepancy {before['discrepancy_px']:.5f} "
              f"± {before['discrepancy_se_px']:.5f} px (DIC of the frames against DIC of the model's frames)")

        step("5. Diagnose", "Fits every candidate effect the model lacks and names the one that explains the "
             "discrepancy (diagnose(rounds=2) would also add it and diagnose again).")
        diagnosis = client.diagnose(dataset_id, model="baseline", schemes=[NATIVE], dic=SMALL_DIC)
        print(f"   verdict: {diagnosis['verdict']}; candidates by drop: {', '.join(diagnosis['ranking_by_drop'][:4])}")
        print(f"   {diagnosis.job['message']}")
        if diagnosis.winner_model_toml:
            model = add_winner(client, diagnosis.winner_model_toml)
            print(f"   added model {model['name']} (version {model['version']}, effects {', '.join(model['effects'])})")
            after = client.compare(dataset_id, model=model["name"], schemes=[NATIVE], dic=SMALL_DIC)
            print(f"   compare with {model['name']}: discrepancy {after['discrepancy_px']:.5f} px")
        else:
            print("   no effect explains the discrepancy: nothing to add")

        step("6. The dataset's history", "Every comparison, oldest first: the discrepancy per model version.")
        for h in client.history(dataset_id):
            print(f"   {h['time']}  {h['model']:<28} {h['version']}  {h['discrepancy_px']:.5f} px  "
                  f"({', '.join(h['effects'])})")
        print("\ndone.")
        return 0
    finally:
        if daemon is not None:
            daemon.stop()
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
