"""Fixtures: a real `ffdic serve` on loopback port 0 with the small mock bench (400x320 px at
13 px/mm, as tests/common/daemon.rs and tests/schemathesis/run.sh use), a second one with a token,
the paper's experiment run once per session, and a small simulated dataset.

The daemon binary is `FFDIC_BIN`, else `target/debug/ffdic` in the repository (`cargo build --bin
ffdic`). The installed package is tested when there is one (the test command installs the
wheel); without it the client is loaded from the source tree, which needs no native module (only
frame decoding does, and that test skips; test_engine.py fails).
"""

from __future__ import annotations

import importlib.util
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any, Dict, Iterator, List, Optional, Tuple

import pytest

PYTHON_DIR = Path(__file__).resolve().parents[1]
REPO = PYTHON_DIR.parent
try:
    # The installed package (`pip install ./python`, as the test command does): client and
    # native module as a user has them.
    import ffdic  # noqa: F401
    import ffdic.client  # noqa: F401
except ImportError:
    sys.path.insert(0, str(PYTHON_DIR))
    sys.modules.pop("ffdic", None)
try:
    import ffdic.client  # noqa: F401,F811  (the source tree's, when nothing is installed)
except ImportError:
    # The package's __init__ needs the native module, not built yet: load the client on its own.
    _spec = importlib.util.spec_from_file_location("ffdic.client", PYTHON_DIR / "ffdic" / "client.py")
    assert _spec is not None and _spec.loader is not None
    _module = importlib.util.module_from_spec(_spec)
    sys.modules["ffdic.client"] = _module
    _spec.loader.exec_module(_module)

from ffdic.client import Client, Event  # noqa: E402

#: The mock bench's frame size, px.
WIDTH_PX = 400
HEIGHT_PX = 320

#: The token of the second daemon.
TOKEN = "s3cret-test-token"

#: The idempotency key the session's paper experiment is submitted with.
PAPER_KEY = "pytest-paper-study"

#: A dataset for `ffdic simulate`: one pattern, a static repeat of the reference and three moves
#: (x 2 mm, x 4 mm, y 3 mm), 320x320 px: small, and enough for a diagnosis to tell a lens
#: distortion from rotation and scale (see tests/api_models.rs).
EXPERIMENT_TOML = """\
name = "pytest-hidden-lens"
seed = 5
patterns = ["a"]
static_frames = 1
schemes = ["ff100"]

[camera]
width = 320
height = 320
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

#: The bench that made it: a barrel distortion the baseline model lacks.
BENCH_TOML = """\
name = "pytest-bench-hidden-lens"
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


def ffdic_binary() -> Path:
    """`FFDIC_BIN`, else the repository's debug build; a missing one fails the session."""
    path = Path(os.environ.get("FFDIC_BIN") or REPO / "target" / "debug" / "ffdic")
    if not path.is_absolute():
        path = REPO / path
    if not (path.is_file() and os.access(path, os.X_OK)):
        pytest.fail(
            f"no ffdic binary at {path}: `cargo build --bin ffdic`, or set FFDIC_BIN",
            pytrace=False,
        )
    return path


class Daemon:
    """`ffdic serve` on 127.0.0.1:0 with the small mock bench in `workdir` (config, data, logs)."""

    def __init__(self, binary: Path, workdir: Path, top_level_toml: str = "") -> None:
        self.binary = binary
        self.workdir = workdir
        self.top_level_toml = top_level_toml
        self.proc: Optional[subprocess.Popen[bytes]] = None
        self.url = ""

    def config_toml(self) -> str:
        data = (self.workdir / "data").as_posix()
        return (
            f'data_dir = "{data}"\n'
            'listen = "127.0.0.1:0"\n'
            f"{self.top_level_toml}"
            "[bench]\n"
            "scale_px_per_mm = 13.0\n"
            "[camera]\n"
            'kind = "mock"\n'
            f"width = {WIDTH_PX}\n"
            f"height = {HEIGHT_PX}\n"
            "[stage]\n"
            'kind = "mock"\n'
            "speed_mm_s = 25.0\n"
            "settle_ms = 10\n"
        )

    def start(self, timeout_s: float = 30.0) -> str:
        self.workdir.mkdir(parents=True, exist_ok=True)
        config = self.workdir / "ffdic.toml"
        config.write_text(self.config_toml())
        env = dict(os.environ)
        env.pop("FFDIC_TOKEN", None)  # it would override the config's token
        env["NO_COLOR"] = "1"
        env.setdefault("RUST_LOG", "info")
        stdout = open(self.workdir / "daemon.stdout", "wb")
        stderr = open(self.workdir / "daemon.stderr", "wb")
        self.proc = subprocess.Popen(
            [str(self.binary), "serve", "--config", str(config)],
            stdout=stdout,
            stderr=stderr,
            stdin=subprocess.DEVNULL,
            env=env,
        )
        stdout.close()
        stderr.close()
        deadline = time.monotonic() + timeout_s
        prefix = "listening on "
        while time.monotonic() < deadline:
            first = (self.workdir / "daemon.stdout").read_text(errors="replace").split("\n", 1)
            if len(first) == 2 and first[0].startswith(prefix):
                self.url = first[0][len(prefix):].strip()
                if "://" not in self.url:
                    self.url = "http://" + self.url
                return self.url
            if self.proc.poll() is not None:
                break
            time.sleep(0.05)
        log = self.log_tail()
        self.stop()
        pytest.fail(f"`ffdic serve` did not start; the end of its log:\n{log}", pytrace=False)

    def log_tail(self, lines: int = 30) -> str:
        try:
            text = (self.workdir / "daemon.stderr").read_text(errors="replace")
        except OSError:
            return ""
        return "\n".join(text.splitlines()[-lines:])

    def stop(self) -> None:
        """SIGTERM (the daemon stops within 10 s), then SIGKILL if it has not."""
        if self.proc is None or self.proc.poll() is not None:
            return
        self.proc.send_signal(signal.SIGTERM)
        try:
            self.proc.wait(timeout=15)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait(timeout=5)


@pytest.fixture(scope="session")
def ffdic_bin() -> Path:
    return ffdic_binary()


@pytest.fixture(scope="session")
def daemon(ffdic_bin: Path, tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    """The base URL of a daemon without a token, for the whole session."""
    d = Daemon(ffdic_bin, tmp_path_factory.mktemp("daemon"))
    url = d.start()
    try:
        yield url
    finally:
        d.stop()
        assert d.proc is not None and d.proc.returncode is not None


@pytest.fixture(scope="session")
def token_daemon(ffdic_bin: Path, tmp_path_factory: pytest.TempPathFactory) -> Iterator[Tuple[str, str]]:
    """`(url, token)` of a daemon whose every request but /health needs the token."""
    d = Daemon(
        ffdic_bin,
        tmp_path_factory.mktemp("token-daemon"),
        f'auth_token = "{TOKEN}"\nread_requires_token = true\n',
    )
    url = d.start()
    try:
        yield url, TOKEN
    finally:
        d.stop()


@pytest.fixture
def client(daemon: str) -> Client:
    return Client(daemon, timeout_s=60)


@pytest.fixture(scope="session")
def paper_run(daemon: str) -> Dict[str, Any]:
    """The paper's experiment (no fields) run once and followed to its end: its id, its final
    record, the progress fractions `follow` reported and the events they came with."""
    c = Client(daemon, timeout_s=60)
    run_id = c.start_experiment(idempotency_key=PAPER_KEY)
    fractions: List[float] = []
    events: List[Event] = []

    def progress(fraction: float, event: Event) -> None:
        fractions.append(fraction)
        events.append(event)

    started = time.monotonic()
    record = c.follow(run_id, progress=progress)
    return {
        "id": run_id,
        "record": record,
        "fractions": fractions,
        "events": events,
        "seconds": time.monotonic() - started,
    }


@pytest.fixture(scope="session")
def simulated_dataset(ffdic_bin: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A dataset folder `ffdic simulate` made of EXPERIMENT_TOML on BENCH_TOML."""
    work = tmp_path_factory.mktemp("simulated")
    (work / "experiment.toml").write_text(EXPERIMENT_TOML)
    (work / "bench.toml").write_text(BENCH_TOML)
    out = work / "dataset"
    env = dict(os.environ, RUST_LOG="warn", NO_COLOR="1")
    done = subprocess.run(
        [
            str(ffdic_bin), "simulate",
            "--experiment", str(work / "experiment.toml"),
            "--model", str(work / "bench.toml"),
            "--out", str(out),
        ],
        capture_output=True,
        env=env,
        timeout=300,
    )
    if done.returncode != 0:
        pytest.fail(f"ffdic simulate failed:\n{done.stderr.decode(errors='replace')}", pytrace=False)
    return out
