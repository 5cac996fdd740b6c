"""The ffdic daemon's bench in Bluesky: ophyd-async devices for its camera and stage, and its
experiments and calibrations as flyers.

The devices talk to a running ``ffdic serve`` through :class:`ffdic.Client` (HTTP on the bench's
network); nothing of the hardware is opened in Python, so a plan and the daemon's dashboard see
the same bench. ::

    import bluesky.plans as bp
    from bluesky import RunEngine
    from ophyd_async.core import init_devices
    import ffdic
    from ffdic.bluesky import Camera, Stage

    client = ffdic.Client("http://127.0.0.1:8080")
    RE = RunEngine()
    with init_devices():
        camera = Camera(client)
        stage = Stage(client)
    RE(bp.scan([camera], stage.x, 0.0, 2.0, 5))   # a frame at each of 5 positions

Needs ``bluesky`` and ``ophyd-async`` (``pip install "ffdic[bluesky]"``). Lengths are in the
daemon's units: stage positions in mm, exposures in µs, intensities in DN (digital numbers).
"""

from __future__ import annotations

import asyncio
import time
from typing import Any, Callable, Dict, List, Mapping, Optional, Tuple, TypeVar

import numpy as np

try:
    from bluesky.protocols import Checkable, Locatable, Location, Stoppable, Triggerable
    from event_model import DataKey
    from ophyd_async.core import (
        AsyncStatus,
        Device,
        StandardReadable,
        StandardReadableFormat,
        WatchableAsyncStatus,
        WatcherUpdate,
        soft_signal_r_and_setter,
        soft_signal_rw,
    )
except ImportError as e:  # pragma: no cover - depends on the environment
    raise ImportError(
        "ffdic.bluesky needs bluesky and ophyd-async: pip install \"ffdic[bluesky]\" "
        f"(missing: {e.name})"
    ) from e

from .client import TERMINAL_EVENTS, Client, RunFailed

__all__ = ["Calibration", "Camera", "Experiment", "LimitsExceeded", "Stage", "StageAxis"]

T = TypeVar("T")

#: The largest code of each pixel format the daemon's cameras deliver, DN: a pixel at it is
#: clipped white.
FULL_SCALE_DN = {"mono8": 255, "mono12": 4095, "mono16": 65535}

#: How often a flyer asks the daemon how its run is going, s.
RUN_POLL_S = 0.2


async def _in_thread(fn: Callable[..., T], *args: Any, **kwargs: Any) -> T:
    """A blocking :class:`Client` call off the RunEngine's event loop."""
    return await asyncio.to_thread(fn, *args, **kwargs)


class LimitsExceeded(ValueError):
    """A stage position outside the travel the daemon's stage reports."""


# --- the camera ------------------------------------------------------------------------------


class Camera(StandardReadable, Triggerable):
    """The daemon's camera as a Bluesky detector.

    ``trigger()`` takes one frame (``POST /camera/snapshot``) with the camera as it is set;
    ``read()`` then gives the frame as a 2-D uint16 array (``image``) and its statistics, in DN:
    ``mean_dn`` (the hint), ``std_dn``, ``min_dn``, ``max_dn``, the fraction of pixels clipped
    white (``saturated_fraction``, at the pixel format's full scale) and black
    (``dark_fraction``, at 0), and ``frame_number`` (the camera's count of completed frames
    after this one). With ``quality=True`` each trigger takes a second frame of the same scene
    and the reading adds the daemon's speckle-quality figures: ``noise_dn`` (temporal noise),
    ``std_u_px`` and ``std_v_px`` (the displacement error that noise predicts for a median
    subset), ``speckle_size_px`` and ``mean_gradient_dn_per_px``.

    The configuration (``read_configuration()``, in every descriptor) is what the camera really
    uses, read from the daemon: ``exposure_us`` and ``gain_db`` (settable:
    ``bps.mv(camera.exposure_us, 5000)`` answers with what the camera set), ``pixel_format``,
    ``model``, ``serial``, ``sensor_width`` and ``sensor_height``.

    ``stage()`` checks that no experiment holds the bench (the daemon would refuse every frame
    with 409 otherwise) and says which run does.
    """

    def __init__(self, client: Client, *, quality: bool = False, name: str = "") -> None:
        self._client = client
        self._quality = quality
        self._info: Optional[Dict[str, Any]] = None
        with self.add_children_as_readables(StandardReadableFormat.HINTED_SIGNAL):
            self.mean_dn, self._set_mean_dn = soft_signal_r_and_setter(float, units="DN")
        with self.add_children_as_readables():
            self.image, self._set_image = soft_signal_r_and_setter(
                np.ndarray, np.zeros((0, 0), dtype=np.uint16), units="DN"
            )
            self.std_dn, self._set_std_dn = soft_signal_r_and_setter(float, units="DN")
            self.min_dn, self._set_min_dn = soft_signal_r_and_setter(int, units="DN")
            self.max_dn, self._set_max_dn = soft_signal_r_and_setter(int, units="DN")
            self.saturated_fraction, self._set_saturated = soft_signal_r_and_setter(float)
            self.dark_fraction, self._set_dark = soft_signal_r_and_setter(float)
            self.frame_number, self._set_frame_number = soft_signal_r_and_setter(int)
        self._quality_setters: Dict[str, Callable[[float], None]] = {}
        if quality:
            with self.add_children_as_readables():
                for key, units in _QUALITY_FIGURES:
                    signal, setter = soft_signal_r_and_setter(float, units=units)
                    setattr(self, key, signal)
                    self._quality_setters[key] = setter
        with self.add_children_as_readables(StandardReadableFormat.CONFIG_SIGNAL):
            self.exposure_us = soft_signal_rw(
                float, units="us", getter=self._setting_getter("exposure_us"),
                setter=self._setting_setter("exposure_us"),
            )
            self.gain_db = soft_signal_rw(
                float, units="dB", getter=self._setting_getter("gain_db"),
                setter=self._setting_setter("gain_db"),
            )
            self.pixel_format = soft_signal_r_and_setter(
                str, getter=self._setting_getter("pixel_format")
            )[0]
            self.model = soft_signal_r_and_setter(str, getter=self._info_getter("model"))[0]
            self.serial = soft_signal_r_and_setter(str, getter=self._info_getter("serial"))[0]
            self.sensor_width = soft_signal_r_and_setter(
                int, units="px", getter=self._info_getter("sensor_width")
            )[0]
            self.sensor_height = soft_signal_r_and_setter(
                int, units="px", getter=self._info_getter("sensor_height")
            )[0]
        super().__init__(name=name)

    def _setting_getter(self, key: str) -> Callable[[], Any]:
        async def get() -> Any:
            camera = await _in_thread(self._client.camera)
            return camera["settings"][key]

        return get

    def _setting_setter(self, key: str) -> Callable[[Any], Any]:
        async def put(value: Any) -> Any:
            applied = await _in_thread(self._client.set_camera, **{key: value})
            return applied[key]

        return put

    def _info_getter(self, key: str) -> Callable[[], Any]:
        async def get() -> Any:
            if self._info is None:
                self._info = (await _in_thread(self._client.camera))["info"]
            return self._info[key]

        return get

    async def _check_bench_free(self) -> None:
        status = await _in_thread(self._client.status)
        holder = status.get("bench", {}).get("holder")
        if holder:
            raise RuntimeError(
                f"the bench is held by run {holder}: its frames are its own until it ends "
                "(cancel it, or wait)"
            )

    @AsyncStatus.wrap
    async def stage(self) -> None:
        await self._check_bench_free()
        await super().stage()

    @AsyncStatus.wrap
    async def trigger(self) -> None:
        snap = await _in_thread(self._client.snapshot, quality=self._quality)
        camera = await _in_thread(self._client.camera)
        image = np.ascontiguousarray(snap.image)
        full_scale = FULL_SCALE_DN.get(str(camera["settings"]["pixel_format"]), int(np.iinfo(image.dtype).max))
        pixels = max(image.size, 1)
        self._set_image(image)
        self._set_mean_dn(float(image.mean()))
        self._set_std_dn(float(image.std()))
        self._set_min_dn(int(image.min()))
        self._set_max_dn(int(image.max()))
        self._set_saturated(float(np.count_nonzero(image >= full_scale)) / pixels)
        self._set_dark(float(np.count_nonzero(image == 0)) / pixels)
        self._set_frame_number(int(camera["counters"]["completed"]))
        if self._quality:
            figures = snap.quality or {}
            for key, setter in self._quality_setters.items():
                value = figures.get(key)
                setter(float(value) if isinstance(value, (int, float)) else float("nan"))


#: The speckle-quality figures a ``Camera(quality=True)`` reads, with their units.
_QUALITY_FIGURES: Tuple[Tuple[str, str], ...] = (
    ("noise_dn", "DN"),
    ("std_u_px", "px"),
    ("std_v_px", "px"),
    ("speckle_size_px", "px"),
    ("mean_gradient_dn_per_px", "DN/px"),
)


# --- the stage -------------------------------------------------------------------------------


class StageAxis(StandardReadable, Locatable[float], Checkable[float]):
    """One axis of the daemon's stage as a Bluesky motor, positions in mm.

    ``set(x)`` moves this axis alone to ``x`` (``POST /stage/moves``, absolute; the other axis
    stays) and is done when the stage has settled; its readback (named as the axis, the hint)
    is the position the daemon reads back. A target outside the travel the stage reports
    (``low_limit_travel``, ``high_limit_travel``, in the configuration, beside ``resolution``:
    the stage's step, to which the daemon rounds a move it is asked for) raises
    :class:`LimitsExceeded` before anything moves, as does ``check_value`` (which
    ``bluesky.simulators.check_limits`` calls for a whole plan).
    """

    def __init__(self, client: Client, axis: str, name: str = "") -> None:
        if axis not in ("x", "y"):
            raise ValueError(f"axis must be 'x' or 'y', not {axis!r}")
        self._client = client
        self._axis = axis
        self._travel_mm: Optional[Tuple[float, float]] = None
        with self.add_children_as_readables(StandardReadableFormat.HINTED_UNCACHED_SIGNAL):
            self.user_readback = soft_signal_r_and_setter(
                float, units="mm", precision=4, getter=self._position_mm
            )[0]
        with self.add_children_as_readables(StandardReadableFormat.CONFIG_SIGNAL):
            self.low_limit_travel = soft_signal_r_and_setter(
                float, units="mm", getter=self._limit_getter(0)
            )[0]
            self.high_limit_travel = soft_signal_r_and_setter(
                float, units="mm", getter=self._limit_getter(1)
            )[0]
            # The step a move is commanded in: the daemon rounds a requested move to it.
            self.resolution = soft_signal_r_and_setter(
                float, units="mm", getter=self._resolution_mm
            )[0]
        self.user_setpoint = soft_signal_rw(float, units="mm")
        super().__init__(name=name)

    def set_name(self, name: str, *, child_name_separator: Optional[str] = None) -> None:
        super().set_name(name, child_name_separator=child_name_separator)
        # The readback carries the axis's own name in events and tables, as a motor's does.
        self.user_readback.set_name(name)

    async def _position_mm(self) -> float:
        stage = await _in_thread(self._client.stage)
        position = stage.get("position")
        if not position:
            raise RuntimeError(f"the daemon cannot read the stage's position: {stage.get('error')}")
        return float(position[f"{self._axis}_mm"])

    async def travel_mm(self) -> Tuple[float, float]:
        """The axis's travel ``(low, high)``, mm, as the daemon's stage reports it."""
        if self._travel_mm is None:
            stage = await _in_thread(self._client.stage)
            low, high = stage["info"][f"travel_{self._axis}_mm"]
            self._travel_mm = (float(low), float(high))
        return self._travel_mm

    async def _resolution_mm(self) -> float:
        stage = await _in_thread(self._client.stage)
        return float(stage["info"].get("resolution_mm", 0.0))

    def _limit_getter(self, index: int) -> Callable[[], Any]:
        async def get() -> float:
            return (await self.travel_mm())[index]

        return get

    async def check_value(self, value: float) -> None:
        low, high = await self.travel_mm()
        if not (np.isfinite(value) and low <= value <= high):
            raise LimitsExceeded(
                f"{self.name or 'stage ' + self._axis}: {value} mm is outside the travel "
                f"[{low}, {high}] mm"
            )

    @AsyncStatus.wrap
    async def set(self, value: float) -> None:
        value = float(value)
        await self.check_value(value)
        await self.user_setpoint.set(value)
        await _in_thread(self._client.move_stage, **{f"{self._axis}_mm": value})

    async def locate(self) -> Location[float]:
        setpoint, readback = await asyncio.gather(
            self.user_setpoint.get_value(), self._position_mm()
        )
        return {"setpoint": setpoint, "readback": readback}


class Stage(Device):
    """The daemon's stage: ``x`` and, on a two-axis stage, ``y`` (:class:`StageAxis` each), and
    ``homed``.

    Most controllers refuse a move until the stage has found its reference (the daemon answers
    409 "home it first"): ``bps.mv(stage.homed, True)`` homes it and is done when it has
    (homing moves the stage, so a plan asks for it; it never happens by itself).
    ``bp.grid_scan([camera], stage.y, 0, 2, 3, stage.x, 0, 2, 3)`` then takes a frame at each
    node. The axes exist whatever the stage reports; moving ``y`` on a one-axis stage is
    refused by the daemon (422).
    """

    def __init__(self, client: Client, name: str = "") -> None:
        self._client = client
        self.x = StageAxis(client, "x")
        self.y = StageAxis(client, "y")
        self.homed = soft_signal_rw(bool, getter=self._homed, setter=self._home)
        super().__init__(name=name)

    async def _homed(self) -> bool:
        return bool((await _in_thread(self._client.stage))["homed"])

    async def _home(self, value: Optional[bool]) -> bool:
        if not value:
            raise ValueError("a stage cannot be un-homed: set homed to True to home it")
        await _in_thread(self._client.move_stage, home=True)
        return await self._homed()


# --- experiments and calibrations as flyers --------------------------------------------------


class _Run(Device, Stoppable):
    """A daemon run as a Bluesky flyer: ``kickoff`` submits it, ``complete`` follows it to its
    end (with its progress as a watcher's fraction), ``collect_pages`` emits its results."""

    def __init__(self, client: Client, name: str = "") -> None:
        self._client = client
        self._run_id: Optional[str] = None
        self._results: Optional[List[Dict[str, Any]]] = None
        self.run_id, self._set_run_id = soft_signal_r_and_setter(str)
        super().__init__(name=name)

    def _submit(self) -> str:
        raise NotImplementedError

    def _rows(self) -> List[Dict[str, Any]]:
        """The run's results, one dict per event, after it succeeded."""
        raise NotImplementedError

    #: The stream the results go to.
    stream = "results"

    @property
    def current_run(self) -> str:
        if self._run_id is None:
            raise RuntimeError(f"{self.name}: not kicked off")
        return self._run_id

    @AsyncStatus.wrap
    async def kickoff(self) -> None:
        self._run_id = await _in_thread(self._submit)
        self._set_run_id(self._run_id)
        self._results = None

    @WatchableAsyncStatus.wrap
    async def complete(self):  # type: ignore[no-untyped-def]
        run_id = self.current_run
        start = time.monotonic()
        while True:
            record = await _in_thread(self._client.job, run_id)
            progress = float(record.get("progress") or 0.0)
            yield WatcherUpdate(
                name=self.name, current=progress, initial=0.0, target=1.0, unit="",
                precision=3, time_elapsed=time.monotonic() - start,
            )
            status = record.get("status")
            if status in TERMINAL_EVENTS:
                if status != "succeeded":
                    raise RunFailed(record)
                break
            await asyncio.sleep(RUN_POLL_S)
        self._results = await _in_thread(self._rows)

    async def stop(self, success: bool = True) -> None:
        """Cancels the run on the daemon if it has not ended (a plan aborted mid-run)."""
        if self._run_id is None:
            return
        record = await _in_thread(self._client.job, self._run_id)
        if record.get("status") not in TERMINAL_EVENTS:
            await _in_thread(self._client.cancel, self._run_id, "job")

    def _collected(self) -> List[Dict[str, Any]]:
        if self._results is None:
            raise RuntimeError(f"{self.name}: collect after complete")
        return self._results

    def describe_collect(self) -> Dict[str, Dict[str, DataKey]]:
        rows = self._collected()
        keys: Dict[str, DataKey] = {}
        for column, value in rows[0].items() if rows else ():
            source = f"ffdic:{self._client.url}/jobs/{self.current_run}"
            if isinstance(value, str):
                keys[f"{self.name}-{column}"] = DataKey(dtype="string", shape=[], source=source)
            elif isinstance(value, (bool, np.bool_)):
                keys[f"{self.name}-{column}"] = DataKey(dtype="boolean", shape=[], source=source)
            elif isinstance(value, (int, np.integer)):
                keys[f"{self.name}-{column}"] = DataKey(dtype="integer", shape=[], source=source)
            else:
                keys[f"{self.name}-{column}"] = DataKey(dtype="number", shape=[], source=source)
        return {self.stream: keys}

    def collect_pages(self):  # type: ignore[no-untyped-def]
        rows = self._collected()
        if not rows:
            return
        now = time.time()
        data = {f"{self.name}-{c}": [r[c] for r in rows] for c in rows[0]}
        yield {
            "data": data,
            "timestamps": {k: [now] * len(rows) for k in data},
            "time": [now] * len(rows),
        }


class Experiment(_Run):
    """An experiment on the daemon's bench as a flyer: ``bp.fly([Experiment(client, request)])``
    runs it and emits its study in the stream ``study``, one event per row of the study's table
    (``results.csv``: run, pattern, scheme, u/v/strain means and stds, …) plus the run's id.

    ``request`` is an ``ExperimentRequest`` as :meth:`Client.start_experiment` takes it (none:
    the paper's study). While it runs the daemon holds the bench: a :class:`Camera` or
    :class:`Stage` in the same plan waits for its end.
    """

    stream = "study"

    def __init__(self, client: Client, request: Optional[Mapping[str, Any]] = None, name: str = "") -> None:
        self._request = dict(request or {})
        super().__init__(client, name=name)

    def _submit(self) -> str:
        return self._client.start_experiment(self._request)

    def _rows(self) -> List[Dict[str, Any]]:
        table = self._client.results_table(self.current_run)
        count = len(next(iter(table.values()))) if table else 0
        rows = []
        for i in range(count):
            row: Dict[str, Any] = {"run_id": self.current_run}
            for column, values in table.items():
                v = values[i]
                row[column] = str(v) if values.dtype.kind in "US" else float(v)
            rows.append(row)
        return rows


class Calibration(_Run):
    """A calibration (``POST /calibrations``: a move plan run on the bench and diagnosed into a
    camera card) as a flyer: ``bp.fly([Calibration(client, plan)])`` emits the card in the
    stream ``card``, one event: the run's id, the stored ``model``'s name, the stage's
    ``scale_x_px_per_mm``, ``scale_y_px_per_mm`` and ``angle_rad`` with their standard errors
    (``*_se_*``), every effect's parameters as ``EFFECT_PARAM`` with ``EFFECT_PARAM_se``, and
    the discrepancy before and with the card (``baseline_px``, ``card_px`` and their ``_se``).
    """

    stream = "card"

    def __init__(self, client: Client, plan: Optional[Mapping[str, Any]] = None, name: str = "") -> None:
        self._plan = dict(plan or {})
        super().__init__(client, name=name)

    def _submit(self) -> str:
        return self._client.start_calibration(self._plan)

    def _rows(self) -> List[Dict[str, Any]]:
        document = self._client.calibration_card(self.current_run)
        return [_card_row(self.current_run, document)]


def _card_row(run_id: str, document: Mapping[str, Any]) -> Dict[str, Any]:
    """A camera card flattened into one event's columns (numbers and the model's name)."""
    card = document["card"]
    row: Dict[str, Any] = {"run_id": run_id, "model": str(document.get("model", ""))}
    for key, value in sorted(card.get("stage", {}).items()):
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            row[f"stage_{key}"] = float(value)
    for group in ("geometry", "imaging"):
        for effect in card.get(group, []):
            stderr = effect.get("stderr", {})
            for param, value in sorted(effect.get("params", {}).items()):
                row[f"{effect['effect']}_{param}"] = float(value)
                se = stderr.get(param)
                row[f"{effect['effect']}_{param}_se"] = float(se) if se is not None else float("nan")
    for key in ("baseline_px", "baseline_se_px", "card_px", "card_se_px"):
        if isinstance(card.get(key), (int, float)):
            row[key] = float(card[key])
    return row
