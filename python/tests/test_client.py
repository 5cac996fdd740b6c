"""`ffdic.Client` against a real `ffdic serve` on the small mock bench (see conftest.py)."""

from __future__ import annotations

import io
import socket
from pathlib import Path
from typing import Any, Dict, Tuple

import numpy as np
import pytest

from conftest import HEIGHT_PX, PAPER_KEY, WIDTH_PX
from ffdic.client import Client, Event, JobResult, ProblemError, RunFailed, _parse_sse

PATTERNS = {"a", "b", "c"}
SCHEMES = {"ff100", "ff50", "ff25"}

#: Native resolution and small subsets: what keeps a comparison of the 320x320 dataset quick.
NATIVE = {"name": "native", "x": {"block": 1, "first": 0, "active": 1}, "y": {"block": 1, "first": 0, "active": 1}}
SMALL_DIC = {"subset_px": 21, "step_px": 10, "strain_window": 5}


# --- the paper's experiment -----------------------------------------------------------------


def test_the_paper_experiment_is_followed_to_100_percent(client: Client, paper_run: Dict[str, Any]) -> None:
    fractions = paper_run["fractions"]
    assert fractions, "follow reported no progress"
    assert all(0.0 <= f <= 1.0 for f in fractions), fractions
    assert all(b >= a for a, b in zip(fractions, fractions[1:])), f"progress went back: {fractions}"
    assert fractions[-1] == 1.0
    events = paper_run["events"]
    assert events[0].event == "queued"
    assert events[-1].event == "succeeded" and events[-1].terminal
    assert {"frame_captured", "pair_analyzed"} <= {e.event for e in events}
    record = paper_run["record"]
    assert record["id"] == paper_run["id"]
    assert record["status"] == "succeeded"
    assert record["progress"] == 1.0
    assert client.experiment(paper_run["id"])["status"] == "succeeded"
    assert paper_run["id"] in [r["id"] for r in client.experiments(status="succeeded")]
    assert paper_run["id"] not in [r["id"] for r in client.experiments(status="failed")]


def test_the_same_idempotency_key_gives_the_same_run(client: Client, paper_run: Dict[str, Any]) -> None:
    assert client.start_experiment(idempotency_key=PAPER_KEY) == paper_run["id"]


def test_results_json_and_table(client: Client, paper_run: Dict[str, Any]) -> None:
    rows = client.results(paper_run["id"])["rows"]
    assert {(r["pattern"], r["scheme"]) for r in rows} == {(p, s) for p in PATTERNS for s in SCHEMES}
    for r in rows:
        # The 5 mm move at 13 px/mm is 65 px; ff100 and ff50/ff25 halve it.
        assert r["u"]["std"] >= 0 and r["v"]["std"] >= 0
        assert r["valid"] > 0

    table = client.results_table(paper_run["id"])
    assert len(table["run"]) == len(rows) == 9
    assert table["pattern"].dtype.kind == "U" and table["scheme"].dtype.kind == "U"
    for column in ("u_std", "v_std", "u_mean", "fill_x", "valid"):
        assert table[column].dtype == np.float64, column
    # A single capture has no interval: NaN, not text.
    assert np.isnan(table["u_std_lo"]).all()
    # The commanded move in each scheme's px (65 px halved by every 2x2 block) and the bias
    # against it.
    assert (table["u_expected"] == 32.5).all() and (table["v_expected"] == 0.0).all()
    assert np.array_equal(table["u_bias"], table["u_mean"] - table["u_expected"])
    by_key = {(r["pattern"], r["scheme"]): r for r in rows}
    for p, s, u_std in zip(table["pattern"], table["scheme"], table["u_std"]):
        assert u_std == pytest.approx(by_key[(str(p), str(s))]["u"]["std"], rel=1e-12)


def test_frames_as_numpy(client: Client, paper_run: Dict[str, Any]) -> None:
    names = client.frames(paper_run["id"])
    assert set(names) == {f"{p}_{m}.tif" for p in PATTERNS for m in ("ref", "x5mm")}
    raw = client.frame_bytes(paper_run["id"], "b_ref.tif")
    assert raw[:4] in (b"II*\x00", b"MM\x00*"), raw[:8]
    try:
        from ffdic._ffdic import decode_tiff  # noqa: F401
    except ImportError:
        pytest.skip("the native module ffdic._ffdic is not built: frame decoding not checked")
    frame = client.frame(paper_run["id"], "b_ref.tif")
    assert frame.shape == (HEIGHT_PX, WIDTH_PX)
    assert frame.dtype == np.uint16
    assert frame.std() > 0


def test_plots_are_svg(client: Client, paper_run: Dict[str, Any]) -> None:
    svg = client.plot(paper_run["id"], "figure5_u.svg")
    assert "<svg" in svg[:500]


# --- the bench ------------------------------------------------------------------------------


def test_health_status_camera_stage(client: Client) -> None:
    assert client.health()["status"] == "ok"
    status = client.status()
    assert {"version", "bench", "experiments_queued", "experiments_running"} <= set(status)
    info = client.camera()["info"]
    assert (info["sensor_width"], info["sensor_height"]) == (WIDTH_PX, HEIGHT_PX)
    assert set(client.stage()["position"]) == {"x_mm", "y_mm"}


# --- problems -------------------------------------------------------------------------------


def test_a_validation_error_is_a_problem_naming_the_field(client: Client) -> None:
    with pytest.raises(ProblemError) as info:
        client.start_experiment(frames_averaged=0)
    err = info.value
    assert err.status == 422
    assert err.field == "frames_averaged"
    assert err.title == "Unprocessable Entity"
    assert err.type.endswith("/validation")
    assert err.problem["status"] == 422
    assert str(err) == f"422 Unprocessable Entity: frames_averaged: {err.detail}"
    assert "\n" not in str(err)


def test_unknown_ids_are_404(client: Client) -> None:
    for call in (
        lambda: client.experiment("exp-20000101t000000-zzzzzz"),
        lambda: client.experiment("no-such-run"),
        lambda: list(client.events("exp-20000101t000000-zzzzzz")),
        lambda: client.dataset("ds-nope"),
        lambda: client.model("no-such-model"),
    ):
        with pytest.raises(ProblemError) as info:
            call()
        assert info.value.status == 404, info.value
        assert info.value.field is None


def test_an_unreachable_daemon_is_a_connection_error() -> None:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    url = f"http://127.0.0.1:{port}"
    with pytest.raises(ConnectionError, match=url.replace(".", r"\.")):
        Client(url, timeout_s=5).health()


def test_the_token(token_daemon: Tuple[str, str]) -> None:
    url, token = token_daemon
    anonymous = Client(url)
    assert anonymous.health()["status"] == "ok"  # the liveness probe stays open
    for call in (
        lambda: anonymous.start_experiment(),
        lambda: anonymous.experiments(),  # this daemon serves reads to token holders only
        lambda: Client(url, token="wrong").move_stage(home=True),
    ):
        with pytest.raises(ProblemError) as info:
            call()
        assert info.value.status == 401, info.value
        assert "Bearer" in info.value.detail

    holder = Client(url, token=token)
    assert holder.experiments() == []
    holder.move_stage(home=True)
    settled = holder.move_stage(dx_mm=1.0)
    assert settled["x_mm"] == pytest.approx(1.0)
    # Past the token check, on to validation: the request itself is what is wrong now.
    with pytest.raises(ProblemError) as info:
        holder.start_experiment(frames_averaged=0)
    assert info.value.status == 422


# --- events ---------------------------------------------------------------------------------


def test_events_resume_after_last_event_id(client: Client, paper_run: Dict[str, Any]) -> None:
    everything = list(client.events(paper_run["id"]))
    assert all(e.id is not None for e in everything)
    ids = [int(e.id or 0) for e in everything]
    assert ids == list(range(1, len(ids) + 1)), ids
    assert everything[-1].event == "succeeded"
    middle = ids[len(ids) // 2]
    later = list(client.events(paper_run["id"], last_event_id=middle))
    assert [e.id for e in later] == [i for i in ids if i > middle]
    assert [e.data for e in later] == [e.data for e in everything if (e.id or 0) > middle]
    # The same run through the job routes.
    assert [e.id for e in client.events(paper_run["id"], kind="job", last_event_id=ids[-2])] == [ids[-1]]


def test_the_event_parser_skips_keep_alives_and_joins_data_lines() -> None:
    stream = io.BytesIO(
        b": keep-alive\n\n"
        b"id: 1\r\nevent: queued\r\ndata: {\"progress\": 0.0,\r\ndata:  \"message\": \"queued\"}\r\n\r\n"
        b":keep-alive\n\n"
        b"id: 2\nevent: note\ndata: not json\ndata: second line\n\n"
        b"event: server_shutdown\ndata: {\"message\": \"bye\"}\n\n"
        b"id: 3\nevent: dangling\n"  # no data, no blank line: never dispatched
    )
    events = list(_parse_sse(stream))
    assert events == [
        Event(1, "queued", {"progress": 0.0, "message": "queued"}),
        Event(2, "note", "not json\nsecond line"),
        Event(None, "server_shutdown", {"message": "bye"}),
    ]
    assert events[0].progress == 0.0 and events[0].message == "queued"
    assert events[1].progress is None and not events[1].terminal


def test_a_cancelled_run_raises_run_failed(client: Client) -> None:
    run_id = client.start_experiment(
        name="to-cancel",
        patterns=["a"],
        moves=[{"id": "x1", "dx_mm": 0.5, "dy_mm": 0.0}, {"id": "x2", "dx_mm": 1.0, "dy_mm": 0.0}],
        settle_ms=500,
        dic=SMALL_DIC,
    )
    client.cancel(run_id)
    with pytest.raises(RunFailed) as info:
        client.follow(run_id)
    err = info.value
    assert isinstance(err, ProblemError)
    assert err.run_status == "cancelled" and err.run["status"] == "cancelled"
    assert err.status is None
    assert run_id in str(err) and "cancelled" in str(err)
    with pytest.raises(ProblemError) as again:
        client.cancel(run_id)
    assert again.value.status == 409


def test_what_one_move_leaves_open_is_resolved_on_the_bench(client: Client) -> None:
    run_id = client.start_experiment(
        name="one move",
        patterns=["a"],
        moves=[{"id": "x2", "dx_mm": 2.0, "dy_mm": 0.0}],
        settle_ms=0,
        dic=SMALL_DIC,
    )
    dataset_id = client.follow(run_id)["dataset_id"]
    doc = client.diagnose_on_bench(dataset_id, schemes=[NATIVE], dic=SMALL_DIC)
    assert doc.job["kind"] == "on_bench" and doc.job["status"] == "succeeded"
    assert "static_repeats" in doc["bench"]["runs"]
    assert doc["bench"]["dataset"] not in (None, dataset_id)
    unrevealed = lambda open_: [n["effect"] for n in open_["not_identifiable"]]  # noqa: E731
    assert "sensor_noise" in unrevealed(doc["open_before"])
    assert "sensor_noise" not in unrevealed(doc["open_after"]), doc.job["message"]
    assert client.dataset(dataset_id)["runs"] == 1
    assert client.dataset(doc["bench"]["dataset"])["runs"] > 1


def test_a_perpendicularity_check_reads_the_mock_benchs_square_target(client: Client) -> None:
    reading = client.check_perpendicularity(pattern="a", dic=SMALL_DIC)
    # The mock bench's target is square to the camera and its stage turned 6.15 mrad.
    for axis in ("y", "x"):
        value, se = reading[f"tilt_about_{axis}_rad"], reading[f"tilt_about_{axis}_se_rad"]
        assert se > 0 and abs(value) < 4 * se, reading
    assert not reading["significant"], reading
    assert abs(reading["stage_angle_rad"] - 0.00615) < 4 * reading["stage_angle_se_rad"] + 2e-4, reading
    assert reading["notes"], reading


# --- datasets and models --------------------------------------------------------------------


def test_upload_compare_diagnose_and_history(client: Client, simulated_dataset: Path) -> None:
    dataset_id = client.upload_dataset(simulated_dataset)
    record = client.dataset(dataset_id)
    assert record["name"] == "pytest-hidden-lens"
    assert record["source"] == "upload"
    assert (record["width"], record["height"]) == (320, 320)
    assert dataset_id in [d["id"] for d in client.datasets()]
    assert client.history(dataset_id) == []

    fractions = []
    before = client.compare(
        dataset_id, schemes=[NATIVE], dic=SMALL_DIC, progress=lambda f, e: fractions.append(f)
    )
    assert isinstance(before, JobResult) and isinstance(before, dict)
    assert {"dataset", "model", "discrepancy_px", "discrepancy_se_px", "runs"} <= set(before)
    assert before.job["status"] == "succeeded" and before.job["kind"] == "comparison"
    assert fractions and fractions[-1] == 1.0
    history = client.history(dataset_id)
    assert len(history) == 1
    assert history[0]["model"] == "baseline"
    assert history[0]["discrepancy_px"] == pytest.approx(before["discrepancy_px"])

    diagnosis = client.diagnose(dataset_id, schemes=[NATIVE], dic=SMALL_DIC)
    assert {"verdict", "verdicts", "candidates", "discrepancy_px", "final_discrepancy_px", "rounds"} <= set(diagnosis)
    assert diagnosis.job["kind"] == "diagnosis"
    assert diagnosis["verdict"] == "lens_distortion", diagnosis.job["message"]
    assert diagnosis.winner_model_toml and "[effects.lens_distortion]" in diagnosis.winner_model_toml
    assert len(client.history(dataset_id)) == 1  # one round: a diagnosis adds no comparison

    added = client.add_model(diagnosis.winner_model_toml)
    assert "lens_distortion" in added["effects"] and added["source"] == "stored"
    assert client.add_model(diagnosis.winner_model_toml)["version"] == added["version"]
    assert added["name"] in [m["name"] for m in client.models()]
    assert client.model(added["name"])["toml"] == diagnosis.winner_model_toml
    with pytest.raises(ProblemError) as info:
        client.add_model('name = "x"\n[effects.psf_blurr]\nsigma_px = 1\n')
    assert info.value.status == 422 and info.value.field == "toml"

    after = client.compare(dataset_id, model=added["name"], schemes=[NATIVE], dic=SMALL_DIC)
    history = client.history(dataset_id)
    assert [h["model"] for h in history] == ["baseline", added["name"]]
    assert after["discrepancy_px"] < before["discrepancy_px"]

    with pytest.raises(ProblemError) as info:
        client.compare(dataset_id, model="no-such-model")
    assert info.value.status == 422 and info.value.field == "model"


def test_analyse_a_dataset(client: Client, simulated_dataset: Path) -> None:
    dataset_id = client.upload_dataset(simulated_dataset)
    job_id = client.analyse(dataset_id, schemes=[NATIVE], dic=SMALL_DIC)
    job = client.follow(job_id, kind="job")
    assert job["status"] == "succeeded" and job["kind"] == "analysis"
    rows = client.results(job_id, kind="job")["rows"]
    assert {r["run"] for r in rows} == {"a-x2", "a-x4", "a-y3"}
    table = client.results_table(job_id, kind="job")
    assert len(table["u_mean"]) == len(rows)
    by_run = dict(zip(table["run"], table["u_mean"]))
    assert by_run["a-x4"] == pytest.approx(52.0, abs=1.0)  # 4 mm at 13 px/mm


def test_a_design_map(client: Client) -> None:
    spec = {
        "name": "tiny",
        "seeds": 2,
        "camera": {"width": 192, "height": 192, "scale_px_per_mm": 26.0},
        "move_mm": [0.5, 0.0],
        "axes": {"dot_diameter_px": [3.0, 6.0], "schemes": ["ff100", "ff50"], "subpixel_x": [0.0, 0.5]},
        "dic": {"subset_px": 21, "step_px": 12, "strain_window": 3},
    }
    run_id = client.start_sweep(spec)
    assert run_id in {r["id"] for r in client.sweeps()}
    job = client.follow(run_id, kind="job")
    assert job["status"] == "succeeded" and job["kind"] == "sweep"
    sweep_map = client.sweep_map(run_id)
    assert sweep_map["tasks"] == 16 and len(sweep_map["cells"]) == 8
    for cell in sweep_map["cells"]:
        u = cell["stats"]["u_std_px"]
        assert cell["n"] == 2 and u["lo"] <= u["mean"] <= u["hi"]
    table = client.sweep_table(run_id)
    assert list(table["scheme"]) == [c["scheme"] for c in sweep_map["cells"]]
    np.testing.assert_allclose(table["u_std_px"], [c["stats"]["u_std_px"]["mean"] for c in sweep_map["cells"]], rtol=1e-12)
    assert client.job_file(run_id, "plots/" + sweep_map["figures"][0]).startswith(b"<svg")
    with pytest.raises(ProblemError) as info:
        client.start_sweep({**spec, "seeds": 0})
    assert info.value.status == 422 and info.value.field == "seeds"


def test_lists_in_pages_and_deletion(client: Client, simulated_dataset: Path) -> None:
    ids = [client.upload_dataset(simulated_dataset) for _ in range(2)]
    listed = [d["id"] for d in client.datasets()]
    assert set(ids) <= set(listed)
    # One item a page: the pages, followed through their Link headers, are the whole list.
    assert [d["id"] for d in client._all_pages("/datasets", {}, page_size=1)] == listed
    client.delete_dataset(ids[0])
    with pytest.raises(ProblemError) as e:
        client.dataset(ids[0])
    assert e.value.status == 404
    assert ids[0] not in [d["id"] for d in client.datasets()]
    client.add_model('name = "pytest-deleted"\n')
    client.delete_model("pytest-deleted")
    with pytest.raises(ProblemError) as e:
        client.model("pytest-deleted")
    assert e.value.status == 404
    with pytest.raises(ProblemError) as e:
        client.delete_model("baseline")
    assert e.value.status == 409
