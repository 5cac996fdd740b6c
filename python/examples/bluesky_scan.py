"""The ffdic bench from Bluesky: a RunEngine scans the stage with the camera as detector, then
runs a small fill-factor experiment as a flyer.

    pip install "./python[bluesky]"
    python python/examples/bluesky_scan.py              # starts `ffdic serve` itself
    python python/examples/bluesky_scan.py --url http://127.0.0.1:8080 [--token T]

Steps: home the stage and set the exposure (``bps.mv``); ``bp.scan`` the stage over 2 mm in x,
a frame at each of 5 positions, printed as Bluesky's LiveTable prints them (the stage's readback
and the frames' mean); the DIC of the first frame against the last (the move in px); then
``bp.fly`` an experiment and print the study rows it emitted. Without ``--url`` it starts a small
mock bench (400x320 px at 13 px/mm) as ``paper_study.py`` does.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path
from typing import Any, Dict, List, Tuple

import numpy as np

import bluesky.plan_stubs as bps
import bluesky.plans as bp
from bluesky import RunEngine
from bluesky.callbacks import LiveTable
from ophyd_async.core import init_devices

import ffdic
from ffdic.bluesky import Camera, Experiment, Stage

sys.path.insert(0, str(Path(__file__).resolve().parent))
from paper_study import LocalDaemon, find_binary  # noqa: E402

SCALE_PX_PER_MM = 13.0


def scan_and_fly(client: ffdic.Client) -> None:
    RE = RunEngine({})
    docs: List[Tuple[str, Dict[str, Any]]] = []
    RE.subscribe(lambda name, doc: docs.append((name, doc)))
    with init_devices():
        camera = Camera(client)
        stage = Stage(client)

    print("\n== scan: the camera at 5 stage positions over 2 mm", flush=True)
    RE(bps.mv(stage.homed, True, camera.exposure_us, 8000.0))
    RE(bp.scan([camera], stage.x, 0.0, 2.0, 5), LiveTable(["stage-x", "camera-mean_dn"]))
    events = [d for n, d in docs if n == "event"]
    first, last = events[0]["data"]["camera-image"], events[-1]["data"]["camera-image"]
    r = ffdic.analyze(first, last, subset=31, step=10, roi=(100, 60, 200, 200))
    ok = np.asarray(r.status) == 0
    moved_mm = events[-1]["data"]["stage-x"] - events[0]["data"]["stage-x"]
    print(f"   DIC of the first frame against the last: u = {np.median(r.u[ok]):.3f} px, "
          f"v = {np.median(r.v[ok]):.3f} px over {ok.sum()} points "
          f"(the stage moved {moved_mm:.3f} mm = {moved_mm * SCALE_PX_PER_MM:.3f} px at 13 px/mm)")

    print("\n== fly: a fill-factor experiment on the daemon, its study emitted as events", flush=True)
    docs.clear()
    with init_devices():
        experiment = Experiment(client, {"name": "bluesky-example", "patterns": ["a", "b"],
                                         "moves": [{"id": "x2", "dx_mm": 2.0, "dy_mm": 0.0}]})
    RE(bp.fly([experiment]))
    page = next(d for n, d in docs if n == "event_page")
    data = page["data"]
    print(f"   run {data['experiment-run_id'][0]}: {len(data['experiment-scheme'])} rows")
    print("   pattern scheme  u_std px   u_bias px  v_bias px (the stage's misalignment)")
    for pattern, scheme, std, bias, v_bias in zip(data["experiment-pattern"], data["experiment-scheme"],
                                                  data["experiment-u_std"], data["experiment-u_bias"],
                                                  data["experiment-v_bias"]):
        print(f"   {pattern:7s} {scheme:6s} {std:9.5f} {bias:+10.5f} {v_bias:+10.5f}")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--url", help="a running daemon (default: start a mock bench)")
    parser.add_argument("--token", help="the daemon's bearer token")
    args = parser.parse_args()
    if args.url:
        scan_and_fly(ffdic.Client(args.url, token=args.token, timeout_s=120))
        return 0
    binary = find_binary()
    if binary is None:
        print("no ffdic binary: set FFDIC_BIN, put ffdic on PATH, or `cargo build`", file=sys.stderr)
        return 2
    with tempfile.TemporaryDirectory(prefix="ffdic-bluesky-") as work:
        daemon = LocalDaemon(binary, Path(work))
        url = daemon.start()
        try:
            print(f"{binary} serve, listening on {url} (mock bench, data removed at the end)")
            scan_and_fly(ffdic.Client(url, timeout_s=120))
        finally:
            daemon.stop()
    return 0


if __name__ == "__main__":
    sys.exit(main())
