"""ffdic.bluesky on a real RunEngine against a real `ffdic serve` (the small mock bench, a daemon
of this module's own so that its moves and frames meet no other test's run): the documents a
plan emits are checked against what the daemon recorded (its frame counter, the stage's
position, the camera's settings, the run's results and card) and against the frames themselves
(a DIC of two scan frames finds the commanded move)."""

from __future__ import annotations

import time
import tomllib
from pathlib import Path
from typing import Any, Dict, Iterator, List, Tuple

import numpy as np
import pytest

bluesky = pytest.importorskip("bluesky")
pytest.importorskip("ophyd_async")

import bluesky.plan_stubs as bps  # noqa: E402
import bluesky.plans as bp  # noqa: E402
from bluesky import RunEngine  # noqa: E402
from bluesky.simulators import check_limits  # noqa: E402
from ophyd_async.core import init_devices  # noqa: E402

import ffdic  # noqa: E402
from ffdic.bluesky import Calibration, Camera, Experiment, LimitsExceeded, Stage  # noqa: E402
from ffdic.client import Client, ProblemError, RunFailed  # noqa: E402

from conftest import HEIGHT_PX, REPO, WIDTH_PX, Daemon  # noqa: E402

#: The mock bench's scale (conftest's daemon config), px/mm.
SCALE_PX_PER_MM = 13.0

#: A small experiment: one pattern, one 2 mm move, the paper's 2x2 binning only.
SMALL_EXPERIMENT = {"name": "bluesky-small", "patterns": ["a"], "schemes": ["ff100"],
                    "moves": [{"id": "x2", "dx_mm": 2.0, "dy_mm": 0.0}]}

#: A small calibration, as tests/api_experiments.rs runs it over HTTP.
SMALL_CALIBRATION = {"name": "bluesky bench", "move_sizes_mm": [0.5, 2.5], "phase_scan_count": 0,
                     "static_frames": 1, "rounds": 1,
                     "dic": {"subset_px": 21, "step_px": 10, "strain_window": 5}}

Documents = List[Tuple[str, Dict[str, Any]]]


@pytest.fixture(scope="module")
def bench(ffdic_bin: Path, tmp_path_factory: pytest.TempPathFactory) -> Iterator[Client]:
    d = Daemon(ffdic_bin, tmp_path_factory.mktemp("bluesky-daemon"))
    url = d.start()
    try:
        yield Client(url, timeout_s=60)
    finally:
        d.stop()


@pytest.fixture(scope="module")
def RE() -> RunEngine:
    return RunEngine({}, call_returns_result=True)


@pytest.fixture(scope="module")
def devices(bench: Client, RE: RunEngine) -> Tuple[Camera, Stage]:
    with init_devices():
        camera = Camera(bench)
        stage = Stage(bench)
    return camera, stage


def run(RE: RunEngine, plan: Any) -> Documents:
    docs: Documents = []
    token = RE.subscribe(lambda name, doc: docs.append((name, doc)))
    try:
        RE(plan)
    finally:
        RE.unsubscribe(token)
    return docs


def named(docs: Documents, name: str) -> List[Dict[str, Any]]:
    return [d for n, d in docs if n == name]


def test_count_emits_frames_with_their_statistics_and_settings(
    bench: Client, RE: RunEngine, devices: Tuple[Camera, Stage]
) -> None:
    camera, _ = devices
    before = bench.camera()["counters"]["completed"]
    docs = run(RE, bp.count([camera], num=3))
    after = bench.camera()

    (start,) = named(docs, "start")
    assert start["plan_name"] == "count" and start["num_points"] == 3
    (descriptor,) = named(docs, "descriptor")
    keys = descriptor["data_keys"]
    assert keys["camera-image"]["shape"] == [HEIGHT_PX, WIDTH_PX]
    assert keys["camera-image"]["dtype_numpy"] == "<u2"
    assert keys["camera-mean_dn"]["units"] == "DN"
    assert descriptor["hints"]["camera"]["fields"] == ["camera-mean_dn"]
    config = descriptor["configuration"]["camera"]["data"]
    assert config["camera-exposure_us"] == after["settings"]["exposure_us"]
    assert config["camera-pixel_format"] == after["settings"]["pixel_format"]
    assert (config["camera-sensor_width"], config["camera-sensor_height"]) == (WIDTH_PX, HEIGHT_PX)
    assert config["camera-model"] == after["info"]["model"]

    events = named(docs, "event")
    assert len(events) == 3
    # The daemon counted exactly the frames the documents hold, one per event, in order.
    assert after["counters"]["completed"] == before + 3
    assert [e["data"]["camera-frame_number"] for e in events] == [before + 1, before + 2, before + 3]
    for e in events:
        image = e["data"]["camera-image"]
        assert image.shape == (HEIGHT_PX, WIDTH_PX) and image.dtype == np.uint16
        assert e["data"]["camera-mean_dn"] == pytest.approx(float(image.mean()), rel=1e-12)
        assert e["data"]["camera-std_dn"] == pytest.approx(float(image.std()), rel=1e-12)
        assert e["data"]["camera-max_dn"] == int(image.max())
        assert e["data"]["camera-min_dn"] == int(image.min())
        assert e["data"]["camera-saturated_fraction"] == np.count_nonzero(image == 65535) / image.size
        assert e["data"]["camera-dark_fraction"] == np.count_nonzero(image == 0) / image.size
    # Three frames of a still scene: the same speckle, different noise.
    first, second = (events[i]["data"]["camera-image"].astype(float) for i in (0, 1))
    assert not np.array_equal(first, second)
    assert np.corrcoef(first.ravel(), second.ravel())[0, 1] > 0.99

    (stop,) = named(docs, "stop")
    assert stop["exit_status"] == "success" and stop["num_events"] == {"primary": 3}


def test_a_scan_moves_the_stage_and_its_frames_show_the_move(
    bench: Client, RE: RunEngine, devices: Tuple[Camera, Stage]
) -> None:
    camera, stage = devices

    assert bench.stage()["homed"] is False

    def plan():  # type: ignore[no-untyped-def]
        yield from bps.mv(stage.homed, True, camera.exposure_us, 5000.0)
        yield from bp.scan([camera], stage.x, 0.0, 2.0, 3)

    docs = run(RE, plan())
    assert bench.stage()["homed"] is True
    assert bench.camera()["settings"]["exposure_us"] == 5000.0
    (descriptor,) = named(docs, "descriptor")
    assert descriptor["configuration"]["camera"]["data"]["camera-exposure_us"] == 5000.0
    travel = bench.stage()["info"]["travel_x_mm"]
    limits = descriptor["configuration"]["stage-x"]["data"]
    assert [limits["stage-x-low_limit_travel"], limits["stage-x-high_limit_travel"]] == travel
    assert limits["stage-x-resolution"] == bench.stage()["info"]["resolution_mm"] > 0
    assert descriptor["data_keys"]["stage-x"]["units"] == "mm"

    events = named(docs, "event")
    readback = [e["data"]["stage-x"] for e in events]
    assert readback == pytest.approx([0.0, 1.0, 2.0], abs=1e-6)
    assert bench.stage()["position"]["x_mm"] == pytest.approx(readback[-1], abs=1e-9)

    # The frames are the frames at those positions: the DIC of the first against the last
    # finds the 2 mm move, 26 px at the bench's 13 px/mm, turned by the mock stage's
    # misalignment (the mock bench's truth, config/models/paper-bench.toml).
    angle_rad = tomllib.loads((REPO / "config" / "models" / "paper-bench.toml").read_text())[
        "effects"]["stage_misalignment"]["angle_rad"]
    ref, moved = (events[i]["data"]["camera-image"] for i in (0, 2))
    result = ffdic.analyze(ref, moved, subset=31, step=10, roi=(100, 60, 200, 200))
    valid = np.asarray(result.status) == 0
    assert valid.sum() > 100
    u, v = np.asarray(result.u)[valid], np.asarray(result.v)[valid]
    move_px = 2.0 * SCALE_PX_PER_MM
    assert np.median(u) == pytest.approx(move_px * np.cos(angle_rad), abs=0.01)
    assert np.median(v) == pytest.approx(move_px * np.sin(angle_rad), abs=0.01)

    RE(bps.mv(stage.x, 0.0, camera.exposure_us, 10000.0))


def test_limits_are_refused_before_the_stage_moves(
    bench: Client, RE: RunEngine, devices: Tuple[Camera, Stage]
) -> None:
    camera, stage = devices
    low, high = bench.stage()["info"]["travel_x_mm"]
    where = bench.stage()["position"]
    with pytest.raises(LimitsExceeded, match="outside the travel"):
        check_limits(bp.scan([camera], stage.x, 0.0, high + 5.0, 3))
    check_limits(bp.scan([camera], stage.x, low, high, 3))  # within: no error
    with pytest.raises(Exception) as raised:
        RE(bps.mv(stage.x, high + 5.0))
    assert "outside the travel" in str(raised.value) or isinstance(raised.value.__cause__, LimitsExceeded)
    assert bench.stage()["position"] == where


def test_an_experiment_as_a_flyer_emits_its_study(bench: Client, RE: RunEngine) -> None:
    with init_devices():
        experiment = Experiment(bench, SMALL_EXPERIMENT)
    docs = run(RE, bp.fly([experiment]))
    (stop,) = named(docs, "stop")
    assert stop["exit_status"] == "success"
    (descriptor,) = named(docs, "descriptor")
    assert descriptor["name"] == "study"
    (page,) = named(docs, "event_page")
    run_id = page["data"]["experiment-run_id"][0]
    record = bench.experiment(run_id)
    assert record["status"] == "succeeded"
    assert record["request"]["name"] == SMALL_EXPERIMENT["name"]
    # Every column of the daemon's own table, value for value.
    table = bench.results_table(run_id)
    for column, values in table.items():
        emitted = page["data"][f"experiment-{column}"]
        if values.dtype.kind in "US":
            assert emitted == [str(v) for v in values], column
        else:
            np.testing.assert_array_equal(np.asarray(emitted, dtype=float), values, err_msg=column)
    assert page["data"]["experiment-u_expected"] == [2.0 * SCALE_PX_PER_MM / 2.0]  # ff100 bins 2x2


def test_a_calibration_as_a_flyer_emits_its_card(bench: Client, RE: RunEngine) -> None:
    with init_devices():
        calibration = Calibration(bench, SMALL_CALIBRATION)
    docs = run(RE, bp.fly([calibration]))
    (descriptor,) = named(docs, "descriptor")
    assert descriptor["name"] == "card"
    (page,) = named(docs, "event_page")
    data = {k.removeprefix("calibration-"): v[0] for k, v in page["data"].items()}
    card = bench.calibration_card(data["run_id"])
    assert data["model"] == card["model"]
    assert bench.model(card["model"])["name"] == card["model"]
    stage = card["card"]["stage"]
    assert data["stage_scale_x_px_per_mm"] == stage["scale_x_px_per_mm"]
    assert data["stage_scale_x_se_px_per_mm"] == stage["scale_x_se_px_per_mm"]
    assert data["stage_angle_rad"] == stage["angle_rad"]
    assert abs(data["stage_scale_x_px_per_mm"] - SCALE_PX_PER_MM) < 0.1
    rotation = next(e for e in card["card"]["geometry"] if e["effect"] == "rotation")
    assert data["rotation_angle_rad"] == rotation["params"]["angle_rad"]
    assert data["rotation_angle_rad_se"] == rotation["stderr"]["angle_rad"]
    assert data["card_px"] == card["card"]["card_px"]


def test_a_refused_run_fails_the_plan(bench: Client, RE: RunEngine) -> None:
    with init_devices():
        bad = Experiment(bench, {"patterns": ["no-such-print"]})
    docs: Documents = []
    RE.subscribe(lambda name, doc: docs.append((name, doc)))
    with pytest.raises(Exception) as raised:
        RE(bp.fly([bad]))
    cause = raised.value if isinstance(raised.value, ProblemError) else raised.value.__cause__
    assert isinstance(cause, ProblemError) and cause.status == 422, repr(raised.value)
    (stop,) = named(docs, "stop")
    assert stop["exit_status"] == "fail"


def test_the_camera_names_the_run_that_holds_the_bench(
    bench: Client, RE: RunEngine, devices: Tuple[Camera, Stage]
) -> None:
    """While an experiment holds the bench, staging the camera fails naming that run (rather
    than a 409 for every frame), and nothing is captured."""
    camera, _ = devices
    long_run = bench.start_experiment(SMALL_EXPERIMENT, repeats=32, name="bluesky-long")
    try:
        deadline = time.monotonic() + 60
        while bench.status()["bench"]["holder"] is None:
            assert bench.experiment(long_run)["status"] in ("queued", "running")
            assert time.monotonic() < deadline, "the experiment never took the bench"
            time.sleep(0.05)
        docs: Documents = []
        token = RE.subscribe(lambda name, doc: docs.append((name, doc)))
        try:
            with pytest.raises(Exception, match=long_run):
                RE(bp.count([camera]))
        finally:
            RE.unsubscribe(token)
        assert named(docs, "event") == []
    finally:
        bench.cancel(long_run)
    with pytest.raises(RunFailed):
        bench.follow(long_run)


def test_a_stopped_flyer_cancels_its_run(bench: Client, RE: RunEngine) -> None:
    with init_devices():
        long = Experiment(bench, {**SMALL_EXPERIMENT, "repeats": 32, "name": "bluesky-stopped"})

    def plan():  # type: ignore[no-untyped-def]
        yield from bps.open_run()
        yield from bps.kickoff(long, wait=True)
        yield from bps.stop(long)
        yield from bps.complete(long, wait=True)
        yield from bps.close_run()

    with pytest.raises(Exception) as raised:
        RE(plan())
    assert "cancelled" in repr(raised.value) or isinstance(raised.value.__cause__, RunFailed)
    deadline = time.monotonic() + 60
    while bench.experiment(long.current_run)["status"] not in ("cancelled", "failed", "succeeded"):
        assert time.monotonic() < deadline
        time.sleep(0.05)
    assert bench.experiment(long.current_run)["status"] == "cancelled"
