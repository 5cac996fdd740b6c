"""A client for the ffdic daemon's HTTP API (``/api/v1``), for lab scripts and notebooks.

Standard library only (``urllib.request``, ``http.client``, ``json``) plus numpy::

    import ffdic

    c = ffdic.Client("http://127.0.0.1:8080")
    run = c.start_experiment()                 # the paper's study on the bench
    c.follow(run, progress=True)               # a one-line percentage until it ends
    table = c.results_table(run)               # column name -> numpy array
    frame = c.frame(run, "a_ref.tif")          # 2-D numpy array, as stored

Every answer outside 2xx raises :class:`ProblemError` (the daemon's RFC 9457 problem document);
a daemon that cannot be reached raises :class:`ConnectionError` naming the URL. Lengths are in the
units the API uses: displacements in pixels, stage moves in millimetres, times in the daemon's
ISO 8601 strings.
"""

from __future__ import annotations

import csv
import http.client
import io
import json
import os
import socket
import sys
import time
import urllib.error
import urllib.parse
import urllib.request
import uuid
from dataclasses import dataclass
from typing import Any, Callable, Dict, Iterator, List, Mapping, Optional, Tuple, Union

import numpy as np

__all__ = ["Client", "ProblemError", "RunFailed", "Event", "JobResult", "Snapshot", "TERMINAL_EVENTS"]

API_PREFIX = "/api/v1"

#: Event names that end a run's event stream.
TERMINAL_EVENTS = frozenset({"succeeded", "failed", "cancelled"})

#: The event the daemon sends last when it shuts down before the run has ended (it has no id).
SHUTDOWN_EVENT = "server_shutdown"
#: How long ``follow`` waits for a run's record to agree with its terminal event, s.
FINAL_RECORD_WAIT_S = 5.0

#: Where a job of each kind writes its headline document.
_JOB_DOCUMENT = {
    "comparison": "results/comparison.json",
    "diagnosis": "results/diagnosis.json",
    "on_bench": "results/on-bench.json",
    "analysis": "results/study.json",
    "experiment": "results/study.json",
}

ProgressCallback = Callable[[float, "Event"], None]


class ProblemError(Exception):
    """An answer outside 2xx: the daemon's problem document (RFC 9457), as attributes.

    Attributes:
        status: the HTTP status (``None`` only for :class:`RunFailed`, which is no HTTP answer).
        type: a URI naming the problem, e.g. ``https://ffdic.invalid/problems/validation``.
        title: the status's reason phrase, e.g. ``Unprocessable Entity``.
        detail: what went wrong, in words the caller can act on.
        field: the request field at fault (validation errors), else ``None``.
        problem: the whole document as the daemon sent it (a dict).
    """

    def __init__(self, problem: Mapping[str, Any], status: Optional[int] = None) -> None:
        self.problem: Dict[str, Any] = dict(problem)
        raw_status = self.problem.get("status", status)
        self.status: Optional[int] = int(raw_status) if isinstance(raw_status, (int, float)) else status
        self.type: str = str(self.problem.get("type", "about:blank"))
        self.title: str = str(
            self.problem.get("title")
            or (http.client.responses.get(self.status, "Error") if self.status else "Error")
        )
        self.detail: str = str(self.problem.get("detail", ""))
        field = self.problem.get("field")
        self.field: Optional[str] = None if field is None else str(field)
        super().__init__(str(self))

    def __str__(self) -> str:
        head = f"{self.status} {self.title}" if self.status is not None else self.title
        parts = [p for p in (self.field, self.detail) if p]
        return f"{head}: {': '.join(parts)}" if parts else head

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.problem!r})"


class RunFailed(ProblemError):
    """A run (experiment or job) that ended ``failed`` or ``cancelled``, raised by
    :meth:`Client.follow` and the methods that follow a job.

    ``status`` is ``None`` (no HTTP error happened); ``detail`` is the run's last message (its
    reason); ``run`` is the run's final record and ``run_status`` its status.
    """

    def __init__(self, run: Mapping[str, Any]) -> None:
        self.run: Dict[str, Any] = dict(run)
        self.run_status: str = str(run.get("status", "failed"))
        word = "cancelled" if self.run_status == "cancelled" else "failed"
        super().__init__(
            {
                "type": f"https://ffdic.invalid/problems/run-{word}",
                "title": f"{run.get('kind', 'run')} {run.get('id', '?')} {word}",
                "status": None,
                "detail": str(run.get("message", "")),
            }
        )


@dataclass(frozen=True)
class Event:
    """One server-sent event of a run.

    Attributes:
        id: the event's id (1, 2, 3… within a run; ``None`` for the daemon's shutdown notice).
            Pass it as ``last_event_id`` to resume after it.
        event: its name: ``queued``, ``started``, ``stage_moved``, ``frame_captured``,
            ``pair_analyzed``, ``progress``, … and last ``succeeded``, ``failed`` or ``cancelled``.
        data: the payload parsed as JSON: a dict with ``id``, ``run_id``, ``kind``, ``progress``
            (0 to 1), ``message``, ``at`` and the event's own ``data``.
    """

    id: Optional[int]
    event: str
    data: Any

    @property
    def progress(self) -> Optional[float]:
        """The run's progress after this event, 0 to 1 (``None`` when the payload has none)."""
        if isinstance(self.data, dict) and isinstance(self.data.get("progress"), (int, float)):
            return float(self.data["progress"])
        return None

    @property
    def message(self) -> str:
        """The event's one-line message (empty when the payload has none)."""
        if isinstance(self.data, dict):
            return str(self.data.get("message", ""))
        return ""

    @property
    def terminal(self) -> bool:
        """Whether this event ends the run (succeeded, failed, cancelled)."""
        return self.event in TERMINAL_EVENTS


class JobResult(dict):  # type: ignore[type-arg]
    """A job's result document (a plain dict of what the job wrote), with the job beside it.

    Attributes:
        job: the job's final record (``id``, ``status``, ``message``, ``result_files`` …).
        winner_model_toml: for a diagnosis with a verdict, the model with the found effects
            added (``results/winner-model.toml``), ready for :meth:`Client.add_model`; else
            ``None``.
    """

    def __init__(
        self,
        document: Mapping[str, Any],
        job: Mapping[str, Any],
        winner_model_toml: Optional[str] = None,
    ) -> None:
        super().__init__(document)
        self.job: Dict[str, Any] = dict(job)
        self.winner_model_toml: Optional[str] = winner_model_toml


@dataclass(frozen=True)
class Snapshot:
    """One frame from :meth:`Client.snapshot`.

    Attributes:
        image: the frame, a 2-D uint16 numpy array (rows = image height), in DN.
        quality: with ``quality=True``, the daemon's speckle-quality figures of the frame (the
            ``X-Speckle-Quality`` header as a dict); else ``None``.
    """

    image: np.ndarray
    quality: Optional[Dict[str, Any]]


def _decode_tiff(data: bytes) -> np.ndarray:
    """A TIFF the daemon sent, as a numpy array, by the native module (the client itself needs
    only the standard library and numpy)."""
    try:
        from ffdic._ffdic import decode_tiff
    except ImportError as e:  # pragma: no cover - depends on the build
        raise ImportError(
            "frames are decoded by the native module ffdic._ffdic, which is not built: "
            "`pip install ./python` (Client.frame_bytes gives a stored frame's raw TIFF)"
        ) from e
    return decode_tiff(data)


def _json_default(value: Any) -> Any:
    """numpy scalars and arrays in a request body become plain JSON numbers and lists."""
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f"{type(value).__name__} is not JSON serialisable")


def _quote(segment: str) -> str:
    return urllib.parse.quote(str(segment), safe="")


class Client:
    """The ffdic daemon, over HTTP.

    Args:
        url: the daemon's address, e.g. ``http://127.0.0.1:8080`` (a trailing ``/api/v1`` is
            accepted too).
        token: the daemon's bearer token (``auth_token`` in its config, or ``FFDIC_TOKEN``);
            sent as ``Authorization: Bearer …`` with every request when given.
        timeout_s: how long one request may wait for the daemon's answer, seconds. Event
            streams wait at least 30 s between two lines (the daemon sends a keep-alive every
            10 s).

    Environment proxies (``http_proxy``…) are not used: the daemon is on the bench's network.
    """

    def __init__(self, url: str, token: Optional[str] = None, timeout_s: float = 30) -> None:
        base = url.strip().rstrip("/")
        if base.endswith(API_PREFIX):
            base = base[: -len(API_PREFIX)]
        if "://" not in base:
            base = "http://" + base
        self.url: str = base
        self.token: Optional[str] = token
        self.timeout_s: float = float(timeout_s)
        self._opener = urllib.request.build_opener(urllib.request.ProxyHandler({}))

    def __repr__(self) -> str:
        return f"Client({self.url!r}{', token=…' if self.token else ''})"

    # --- plumbing ---------------------------------------------------------------------------

    def _url(self, path: str, query: Optional[Mapping[str, Any]] = None) -> str:
        url = f"{self.url}{API_PREFIX}{path}"
        if query:
            q = {k: v for k, v in query.items() if v is not None}
            if q:
                url += "?" + urllib.parse.urlencode(q)
        return url

    def _open(
        self,
        method: str,
        path: str,
        *,
        json_body: Any = None,
        data: Any = None,
        headers: Optional[Mapping[str, str]] = None,
        query: Optional[Mapping[str, Any]] = None,
        timeout_s: Optional[float] = None,
    ) -> http.client.HTTPResponse:
        """Sends one request; a 2xx answer is returned open, anything else raised."""
        url = self._url(path, query)
        h: Dict[str, str] = {"Accept": "application/json, application/problem+json;q=0.9, */*;q=0.5"}
        if self.token:
            h["Authorization"] = f"Bearer {self.token}"
        if json_body is not None:
            data = json.dumps(json_body, allow_nan=False, default=_json_default).encode("utf-8")
            h["Content-Type"] = "application/json"
        if headers:
            h.update(headers)
        req = urllib.request.Request(url, data=data, headers=h, method=method)
        timeout = self.timeout_s if timeout_s is None else timeout_s
        try:
            return self._opener.open(req, timeout=timeout)  # type: ignore[no-any-return]
        except urllib.error.HTTPError as e:
            raise self._problem(e) from None
        except urllib.error.URLError as e:
            reason = e.reason
            if isinstance(reason, (socket.timeout, TimeoutError)):
                raise TimeoutError(
                    f"the ffdic daemon at {self.url} did not answer {method} {path} "
                    f"within {timeout:g} s"
                ) from None
            raise ConnectionError(f"cannot reach the ffdic daemon at {self.url}: {reason}") from None
        except (socket.timeout, TimeoutError):
            raise TimeoutError(
                f"the ffdic daemon at {self.url} did not answer {method} {path} within {timeout:g} s"
            ) from None
        except (http.client.HTTPException, ConnectionError, OSError) as e:
            raise ConnectionError(
                f"lost the connection to the ffdic daemon at {self.url} ({method} {path}): {e}"
            ) from None

    @staticmethod
    def _problem(e: urllib.error.HTTPError) -> ProblemError:
        try:
            body = e.read()
        except Exception:  # noqa: BLE001 - the status alone still makes an error
            body = b""
        finally:
            e.close()
        try:
            doc = json.loads(body.decode("utf-8"))
        except (ValueError, UnicodeDecodeError):
            doc = None
        if not isinstance(doc, dict) or "status" not in doc:
            text = body.decode("utf-8", "replace").strip()
            doc = {
                "type": "about:blank",
                "title": http.client.responses.get(e.code, e.reason or "Error"),
                "status": e.code,
                "detail": text[:500] if text else str(e.reason or ""),
            }
        return ProblemError(doc, status=e.code)

    def _bytes(self, method: str, path: str, **kw: Any) -> bytes:
        return self._bytes_and_headers(method, path, **kw)[0]

    def _bytes_and_headers(self, method: str, path: str, **kw: Any) -> Tuple[bytes, Any]:
        """The body of a 2xx answer and its headers (an ``email.message.Message``)."""
        resp = self._open(method, path, **kw)
        try:
            return resp.read(), resp.headers
        except (http.client.HTTPException, OSError) as e:
            raise ConnectionError(
                f"lost the connection to the ffdic daemon at {self.url} ({method} {path}): {e}"
            ) from None
        finally:
            resp.close()

    def _json(self, method: str, path: str, **kw: Any) -> Any:
        body = self._bytes(method, path, **kw)
        if not body:
            return None
        return json.loads(body.decode("utf-8"))

    def _all_pages(
        self, path: str, query: Mapping[str, Any], page_size: int = 1000
    ) -> List[Dict[str, Any]]:
        """Every item of a newest-first list, following each page's ``Link: <…>; rel="next"``."""
        items: List[Dict[str, Any]] = []
        next_query: Optional[Dict[str, Any]] = {**query, "limit": page_size}
        while next_query is not None:
            resp = self._open("GET", path, query=next_query)
            try:
                link = resp.headers.get("Link")
                items.extend(json.loads(resp.read().decode("utf-8")))
            finally:
                resp.close()
            next_query = None
            if link and 'rel="next"' in link:
                target = link.split(">", 1)[0].lstrip("<")
                parsed = urllib.parse.urlsplit(target)
                next_query = dict(urllib.parse.parse_qsl(parsed.query))
        return items

    def _submit(self, path: str, body: Mapping[str, Any], idempotency_key: Optional[str]) -> str:
        headers = {"Idempotency-Key": idempotency_key} if idempotency_key else None
        record = self._json("POST", path, json_body=dict(body), headers=headers)
        return str(record["id"])

    @staticmethod
    def _events_path(run_id: str, kind: str) -> str:
        if kind == "experiment":
            return f"/experiments/{_quote(run_id)}"
        if kind == "job":
            return f"/jobs/{_quote(run_id)}"
        raise ValueError(f"kind must be 'experiment' or 'job', not {kind!r}")

    # --- system and bench -------------------------------------------------------------------

    def health(self) -> Dict[str, Any]:
        """``GET /health``: ``{"status": "ok" | "degraded", "version", "stopped": [...]}``.

        Never touches the hardware. A degraded daemon answers 503 with the same document, which
        is returned rather than raised (``stopped`` names what has stopped).
        """
        try:
            return self._json("GET", "/health")  # type: ignore[no-any-return]
        except ProblemError as e:
            if e.status == 503 and "stopped" in e.problem:
                return e.problem
            raise

    def status(self) -> Dict[str, Any]:
        """``GET /status``: version, the bench (camera, stage, who holds it), the number of
        queued and running experiments, and the daemon's data folder."""
        return self._json("GET", "/status")  # type: ignore[no-any-return]

    def camera(self) -> Dict[str, Any]:
        """``GET /camera``: the camera's info (sensor size in px, exposure range in µs, pixel
        formats), its settings and its frame counters."""
        return self._json("GET", "/camera")  # type: ignore[no-any-return]

    def set_camera(self, **settings: Any) -> Dict[str, Any]:
        """``PATCH /camera`` with ``settings`` (``exposure_us``, ``gain_db``, ``pixel_format``,
        ``roi``, ``binning``); returns what the camera really set. 409 while an experiment holds
        the bench."""
        return self._json("PATCH", "/camera", json_body=settings)  # type: ignore[no-any-return]

    def snapshot(self, *, quality: bool = False, subset_px: Optional[int] = None) -> "Snapshot":
        """``POST /camera/snapshot``: one frame from the camera as it is set now, as a 2-D numpy
        array (rows = image height, uint16 as the daemon's 16-bit TIFF holds it), decoded by the
        native module ``ffdic._ffdic.decode_tiff``. With ``quality=True`` the daemon takes a
        second frame of the same scene and :attr:`Snapshot.quality` holds the speckle-quality
        figures of the first (mean intensity gradient, speckle size, SSSIG over ``subset_px``
        subsets, the temporal noise ``noise_dn`` and the displacement error ``std_u_px``,
        ``std_v_px`` it predicts). 409 while an experiment holds the bench."""
        query: Dict[str, Any] = {"format": "tiff"}
        if quality:
            query["quality"] = "true"
        if subset_px is not None:
            query["subset_px"] = int(subset_px)
        data, headers = self._bytes_and_headers("POST", "/camera/snapshot", query=query)
        header = headers.get("X-Speckle-Quality")
        return Snapshot(_decode_tiff(data), json.loads(header) if header else None)

    def stage(self) -> Dict[str, Any]:
        """``GET /stage``: the stage's info (axes, travel in mm), position in mm and whether it
        is homed. 503 when the daemon has no stage."""
        return self._json("GET", "/stage")  # type: ignore[no-any-return]

    def move_stage(
        self,
        *,
        x_mm: Optional[float] = None,
        y_mm: Optional[float] = None,
        dx_mm: Optional[float] = None,
        dy_mm: Optional[float] = None,
        home: bool = False,
    ) -> Dict[str, Any]:
        """``POST /stage/moves``: an absolute (``x_mm``, ``y_mm``) or relative (``dx_mm``,
        ``dy_mm``) move in mm, or ``home=True``; waits until the stage has settled and returns
        where it settled (``{"x_mm", "y_mm"}``)."""
        body: Dict[str, Any] = {
            k: v
            for k, v in (("x_mm", x_mm), ("y_mm", y_mm), ("dx_mm", dx_mm), ("dy_mm", dy_mm))
            if v is not None
        }
        if home:
            body["home"] = True
        return self._json("POST", "/stage/moves", json_body=body)  # type: ignore[no-any-return]

    # --- experiments ------------------------------------------------------------------------

    def start_experiment(
        self,
        request: Optional[Mapping[str, Any]] = None,
        *,
        idempotency_key: Optional[str] = None,
        **fields: Any,
    ) -> str:
        """``POST /experiments``: queues an experiment and returns its run id.

        With no request and no fields it runs the paper's study (patterns a, b, c; one 5 mm
        move along x; schemes ff100, ff50, ff25). ``request`` and ``fields`` are merged (fields
        win) into an ``ExperimentRequest``: ``name``, ``patterns``, ``moves`` (``[{"id",
        "dx_mm", "dy_mm"}]``), ``static_frames``, ``repeats``, ``frames_averaged`` (1 to 64),
        ``settle_ms``, ``exposure_us``, ``schemes``, ``dic`` (``subset_px``, ``step_px``, …),
        ``seed``. An ``idempotency_key`` makes the submission repeat-safe: the same key returns
        the run made the first time.
        """
        body: Dict[str, Any] = dict(request or {})
        body.update(fields)
        return self._submit("/experiments", body, idempotency_key)

    def experiment(self, run_id: str) -> Dict[str, Any]:
        """``GET /experiments/{id}``: the run's record: ``status`` (queued, running, succeeded,
        failed, cancelled), ``progress`` (0 to 1), ``message``, times, the ``request`` as
        submitted, ``dataset_id`` (the frames as a dataset, once written) and ``result_files``."""
        return self._json("GET", f"/experiments/{_quote(run_id)}")  # type: ignore[no-any-return]

    def experiments(
        self, status: Optional[str] = None, limit: Optional[int] = None, after: Optional[str] = None
    ) -> List[Dict[str, Any]]:
        """``GET /experiments``: experiment records, newest first; ``status`` filters (queued,
        running, succeeded, failed, cancelled), ``limit`` caps the count (daemon default 50,
        at most 1000) and ``after`` is the cursor of the page before (its ``Link`` header).
        Every record: :meth:`all_experiments`."""
        return self._json(  # type: ignore[no-any-return]
            "GET", "/experiments", query={"status": status, "limit": limit, "after": after}
        )

    def all_experiments(self, status: Optional[str] = None) -> List[Dict[str, Any]]:
        """Every experiment record, newest first, page after page."""
        return self._all_pages("/experiments", {"status": status})

    def delete_run(self, run_id: str) -> None:
        """``DELETE /jobs/{id}``: deletes an ended run of any kind with its folder (409 while
        it is queued or running: cancel it first). A dataset its frames became stays."""
        self._bytes("DELETE", f"/jobs/{_quote(run_id)}")

    def cancel(self, run_id: str, kind: str = "experiment") -> Dict[str, Any]:
        """``POST /experiments/{id}/cancel`` (``kind="job"``: ``/jobs/{id}/cancel``): asks the run
        to stop and returns its record (its status turns ``cancelled`` shortly after). 409 when
        it has already ended."""
        return self._json("POST", f"{self._events_path(run_id, kind)}/cancel")  # type: ignore[no-any-return]

    # --- calibrations -----------------------------------------------------------------------

    def start_calibration(
        self,
        plan: Optional[Mapping[str, Any]] = None,
        *,
        idempotency_key: Optional[str] = None,
        **fields: Any,
    ) -> str:
        """``POST /calibrations``: queues a calibration (a move plan run on the bench, then
        diagnosed in rounds into a camera card) and returns its run id. ``plan`` and ``fields``
        are merged (fields win) into a ``CalibrationPlan``: ``name``, ``pattern``,
        ``print_characterised``, ``move_sizes_mm``, ``phase_scan_step_px``, ``phase_scan_count``
        (unset: 4 with a characterised print, none without), ``static_frames``,
        ``rounds`` (1 to 8), ``model``, ``dic``, ``seed``. Follow it with
        ``follow(run_id, kind="job")``; its card is :meth:`calibration_card`."""
        body: Dict[str, Any] = dict(plan or {})
        body.update(fields)
        return self._submit("/calibrations", body, idempotency_key)

    def calibration_card(self, run_id: str) -> Dict[str, Any]:
        """``GET /calibrations/{id}/card``: the camera card of a calibration that succeeded:
        ``card`` (``stage``: scale per axis and the stage's angle with standard errors;
        ``geometry`` and ``imaging``: each effect's ``params`` and ``stderr``; the discrepancy
        before and with the card), ``model`` (the stored model's name), ``rounds``, ``plan``
        and ``experiment``. 404 until the card is written."""
        return self._json("GET", f"/calibrations/{_quote(run_id)}/card")  # type: ignore[no-any-return]

    def check_perpendicularity(
        self,
        *,
        progress: Union[ProgressCallback, bool, None] = None,
        idempotency_key: Optional[str] = None,
        **fields: Any,
    ) -> Dict[str, Any]:
        """``POST /perpendicularity-checks``, followed to its end: the mounted target moved along
        +x and −x, and the reading of ``GET /perpendicularity-checks/{id}/reading`` —
        ``tilt_about_y_rad``, ``tilt_about_x_rad`` (each with ``…_se_rad``) at
        ``working_distance_mm`` (``working_distance_stated``), ``stage_angle_rad`` with
        ``stage_angle_se_rad``, ``significant``, ``notes``. ``fields``: ``pattern``, ``move_mm``
        (0: the default), ``dic``, ``seed``. Raises :class:`RunFailed` when the check fails."""
        run_id = self._submit("/perpendicularity-checks", dict(fields), idempotency_key)
        self.follow(run_id, progress=progress, kind="job")
        return self._json("GET", f"/perpendicularity-checks/{_quote(run_id)}/reading")  # type: ignore[no-any-return]

    # --- events -----------------------------------------------------------------------------

    def events(
        self,
        run_id: str,
        *,
        last_event_id: Optional[int] = None,
        kind: str = "experiment",
        reconnects: int = 3,
    ) -> Iterator[Event]:
        """The run's server-sent events (``GET /experiments/{id}/events``, or
        ``/jobs/{id}/events`` with ``kind="job"``), as :class:`Event` objects.

        Every stored event after ``last_event_id`` (all of them when ``None``) comes first, then
        the live ones; the generator ends after the terminal event (``succeeded``, ``failed``,
        ``cancelled``), or after ``server_shutdown`` when the daemon stops first. Keep-alive
        comments are skipped. A connection that breaks mid-stream is reopened from the last event
        seen (``Last-Event-ID``), up to ``reconnects`` times in a row.
        """
        path = f"{self._events_path(run_id, kind)}/events"
        last = last_event_id
        failures = 0
        while True:
            headers = {"Accept": "text/event-stream"}
            if last is not None:
                headers["Last-Event-ID"] = str(int(last))
            resp = self._open("GET", path, headers=headers, timeout_s=max(self.timeout_s, 30.0))
            progressed = False
            try:
                for ev in _parse_sse(resp):
                    if ev.id is not None:
                        last = ev.id
                    progressed = True
                    yield ev
                    if ev.terminal or ev.event == SHUTDOWN_EVENT:
                        return
            except (http.client.HTTPException, OSError) as e:
                broken: Optional[BaseException] = e
            else:
                broken = None
            finally:
                resp.close()
            failures = 0 if progressed else failures + 1
            if failures > reconnects:
                raise ConnectionError(
                    f"the event stream of {run_id} from {self.url} ended before the run did"
                    + (f": {broken}" if broken else "")
                )

    def follow(
        self,
        run_id: str,
        progress: Union[ProgressCallback, bool, None] = None,
        kind: str = "experiment",
    ) -> Dict[str, Any]:
        """Follows a run to its end over its events and returns its final record.

        ``progress`` is called as ``progress(fraction, event)`` for every event (fraction 0 to 1,
        non-decreasing); ``progress=True`` prints a one-line percentage instead. Raises
        :class:`RunFailed` (a :class:`ProblemError`) with the run's reason when it ended failed
        or cancelled, and :class:`ConnectionError` when the daemon shut down first.
        """
        printer = _ProgressLine(run_id) if progress is True else None
        callback: Optional[ProgressCallback] = printer if printer else (
            progress if callable(progress) else None
        )
        end: Optional[Event] = None
        try:
            for ev in self.events(run_id, kind=kind):
                fraction = ev.progress
                if callback is not None and fraction is not None:
                    callback(fraction, ev)
                if ev.terminal or ev.event == SHUTDOWN_EVENT:
                    end = ev
        finally:
            if printer:
                printer.close()
        path = self._events_path(run_id, kind)
        record: Dict[str, Any] = self._json("GET", path)
        # The store writes a run's terminal event before its record (so that a crash between the
        # two is completed from the event at the next start): a record read at once may still
        # say "running". Wait, briefly, for the record to agree with the event.
        deadline = time.monotonic() + FINAL_RECORD_WAIT_S
        while (
            end is not None
            and end.terminal
            and record.get("status") not in TERMINAL_EVENTS
            and time.monotonic() < deadline
        ):
            time.sleep(0.02)
            record = self._json("GET", path)
        if end is not None and end.event == SHUTDOWN_EVENT and record.get("status") not in TERMINAL_EVENTS:
            raise ConnectionError(
                f"the ffdic daemon at {self.url} shut down before {run_id} ended "
                f"(it is {record.get('status')}; its record stays in the store)"
            )
        if record.get("status") in ("failed", "cancelled"):
            raise RunFailed(record)
        return record

    # --- results ----------------------------------------------------------------------------

    def _results_path(self, run_id: str, kind: str, name: str) -> str:
        if kind == "experiment":
            suffix = {"study.json": "results", "study.csv": "results.csv"}[name]
            return f"/experiments/{_quote(run_id)}/{suffix}"
        return f"/jobs/{_quote(run_id)}/files/results/{_quote(name)}"

    def results(self, run_id: str, kind: str = "experiment") -> Dict[str, Any]:
        """``GET /experiments/{id}/results`` (``kind="job"``: an analysis's
        ``results/study.json``): the study, ``{"rows": [...]}`` with one row per pattern, move and
        scheme: ``run``, ``pattern``, ``scheme``, ``fill_factor`` ([x, y]), ``valid`` and
        ``points`` (DIC points), and for ``u``, ``v`` (px) and ``exx``, ``eyy``, ``exy``
        (strain) a ``{"mean", "std", "ci95"}`` (``ci95`` is the 95 % interval of the std over
        repeats, ``[null, null]`` for a single capture); ``increase_pct`` against ff100."""
        return self._json("GET", self._results_path(run_id, kind, "study.json"))  # type: ignore[no-any-return]

    def results_table(self, run_id: str, kind: str = "experiment") -> Dict[str, np.ndarray]:
        """``GET /experiments/{id}/results.csv`` as columns: column name -> numpy array, one
        entry per row. Numeric columns are float64 (``NaN`` where the CSV has none or NaN, e.g.
        ``u_std_lo``/``u_std_hi`` for a single capture); text columns (``run``, ``pattern``,
        ``scheme``) are numpy string arrays. ``u_*``/``v_*`` are px, ``e*`` strains."""
        raw = self._bytes("GET", self._results_path(run_id, kind, "study.csv"))
        return parse_csv_columns(raw.decode("utf-8"))

    def frames(self, run_id: str) -> List[str]:
        """The names of the frames an experiment stored (``a_ref.tif``, ``a_x5mm.tif`` …), from
        its record's ``result_files``: what :meth:`frame` fetches."""
        record = self.experiment(run_id)
        names = []
        for f in record.get("result_files", []):
            folder, _, name = str(f).partition("/")
            if folder == "frames" and name.lower().endswith((".tif", ".tiff")):
                names.append(name)
        return names

    def frame_bytes(self, run_id: str, name: str) -> bytes:
        """``GET /experiments/{id}/frames/{name}``: the stored frame file as sent (a 16-bit TIFF;
        ``dataset.json`` is served the same way)."""
        return self._bytes("GET", f"/experiments/{_quote(run_id)}/frames/{_quote(name)}")

    def frame(self, run_id: str, name: str) -> np.ndarray:
        """An experiment's stored frame as a 2-D numpy array (rows = image height), uint16 or
        float32 as stored, decoded by the native module ``ffdic._ffdic.decode_tiff``."""
        return _decode_tiff(self.frame_bytes(run_id, name))

    def plot(self, run_id: str, name: str) -> str:
        """``GET /experiments/{id}/plots/{name}``: an SVG figure as text, e.g. ``figure5_u.svg``,
        ``figure5_exx.svg``, ``figure6_v.svg``, ``figure6_eyy.svg``."""
        return self._bytes("GET", f"/experiments/{_quote(run_id)}/plots/{_quote(name)}").decode("utf-8")

    # --- jobs -------------------------------------------------------------------------------

    def job(self, job_id: str) -> Dict[str, Any]:
        """``GET /jobs/{id}``: any run's record (comparison, diagnosis, analysis or experiment)."""
        return self._json("GET", f"/jobs/{_quote(job_id)}")  # type: ignore[no-any-return]

    def job_file(self, job_id: str, path: str) -> bytes:
        """``GET /jobs/{id}/files/{folder}/{name}``: a file the run wrote, ``path`` as in its
        ``result_files`` (``results/comparison.json``, ``plots/residual_vs_x.svg`` …)."""
        folder, _, name = path.partition("/")
        return self._bytes("GET", f"/jobs/{_quote(job_id)}/files/{_quote(folder)}/{_quote(name)}")

    def _dataset_job(
        self,
        dataset_id: str,
        kind: str,
        body: Mapping[str, Any],
        idempotency_key: Optional[str],
        progress: Union[ProgressCallback, bool, None],
    ) -> JobResult:
        """``POST /datasets/{id}/{kind}`` with ``body``, followed to its end: its results."""
        job_id = self._submit(f"/datasets/{_quote(dataset_id)}/{kind}", body, idempotency_key)
        return self._job_result(job_id, progress)

    def _job_result(self, job_id: str, progress: Union[ProgressCallback, bool, None]) -> JobResult:
        job = self.follow(job_id, progress=progress, kind="job")
        doc_path = _JOB_DOCUMENT.get(str(job.get("kind")), "results/study.json")
        document = json.loads(self.job_file(job_id, doc_path).decode("utf-8"))
        winner = None
        if "results/winner-model.toml" in job.get("result_files", []):
            winner = self.job_file(job_id, "results/winner-model.toml").decode("utf-8")
        return JobResult(document, job, winner)

    # --- design maps ------------------------------------------------------------------------

    def start_sweep(
        self,
        spec: Mapping[str, Any],
        *,
        idempotency_key: Optional[str] = None,
    ) -> str:
        """``POST /sweeps``: queues a design map on the daemon's compute lane and returns its
        run id. ``spec`` has the fields of ``config/sweeps/*.toml`` (``name``, ``seeds``,
        ``camera``, ``move_mm``, ``axes`` with ``dot_diameter_px`` or ``patterns``,
        ``schemes``, ``noise``, ``psf_sigma_px``, ``subpixel_x``/``subpixel_y``, ``model``,
        ``dic``); ``tomllib.load`` of such a file is one. The daemon caps a sweep (``[sweeps]``
        in its config); larger ones belong to ``ffdic sweep``. Follow it with
        ``follow(id, kind="job")`` and read it with :meth:`sweep_map`."""
        return self._submit("/sweeps", spec, idempotency_key)

    def sweeps(self, status: Optional[str] = None, limit: Optional[int] = None) -> List[Dict[str, Any]]:
        """``GET /sweeps``: design-map records, newest first (filters as :meth:`experiments`)."""
        return self._json("GET", "/sweeps", query={"status": status, "limit": limit})  # type: ignore[no-any-return]

    def sweep_map(self, run_id: str) -> Dict[str, Any]:
        """``GET /sweeps/{id}/map``: the merged map of a finished sweep: ``cells`` (each with
        its axes, ``n`` realisations and ``stats``: ``{name: {"mean", "lo", "hi"}}``, a 95 %
        Student-t interval over realisations, px or strain), ``recommendations`` and the names of
        its ``figures`` (SVG, ``job_file(id, "plots/NAME")``)."""
        return self._json("GET", f"/sweeps/{_quote(run_id)}/map")  # type: ignore[no-any-return]

    def sweep_table(self, run_id: str) -> Dict[str, np.ndarray]:
        """``GET /sweeps/{id}/map.csv`` as columns (as :meth:`results_table`): one entry per
        cell; ``u_std_px``, ``u_std_px_lo``, ``u_std_px_hi`` … are each statistic's mean and
        interval bounds."""
        raw = self._bytes("GET", f"/sweeps/{_quote(run_id)}/map.csv")
        return parse_csv_columns(raw.decode("utf-8"))

    # --- datasets ---------------------------------------------------------------------------

    def upload_dataset(self, folder: Union[str, "os.PathLike[str]"]) -> str:
        """``POST /datasets`` (multipart): uploads a dataset folder and returns its dataset id.

        Sends ``dataset.json`` and every frame it names (references, deformed frames, static
        repeats), one part each, streamed from disk; other files in the folder stay behind (the
        daemon refuses parts its manifest does not name). 422 names an invalid manifest or a
        missing or corrupt frame; 413/507 a dataset over the daemon's limits.
        """
        root = os.fspath(folder)
        manifest_path = os.path.join(root, "dataset.json")
        with open(manifest_path, "rb") as f:
            manifest = json.loads(f.read().decode("utf-8"))
        names: List[str] = ["dataset.json"]
        for run in manifest.get("runs", []):
            for name in [run.get("reference"), run.get("deformed"), *run.get("repeat", [])]:
                if isinstance(name, str) and name not in names:
                    names.append(name)
        paths = [(n, os.path.join(root, n)) for n in names]
        missing = [n for n, p in paths if not os.path.isfile(p)]
        if missing:
            raise FileNotFoundError(f"{root}: dataset.json names frames that are not there: {', '.join(missing)}")
        body, length, content_type = _multipart(paths)
        record = self._json(
            "POST",
            "/datasets",
            data=body,
            headers={"Content-Type": content_type, "Content-Length": str(length)},
            timeout_s=max(self.timeout_s, 120.0),
        )
        return str(record["id"])

    def datasets(self) -> List[Dict[str, Any]]:
        """``GET /datasets``: every stored dataset, newest first, page after page (``id``,
        ``name``, ``source`` — ``upload`` or ``experiment:{run id}`` —, ``runs``,
        ``width``/``height`` in px, ``files``)."""
        return self._all_pages("/datasets", {})

    def delete_dataset(self, dataset_id: str) -> None:
        """``DELETE /datasets/{id}``: deletes a dataset's frames and record (409 while a queued
        or running run names it). Ended runs that analysed it keep their results."""
        self._bytes("DELETE", f"/datasets/{_quote(dataset_id)}")

    def dataset(self, dataset_id: str) -> Dict[str, Any]:
        """``GET /datasets/{id}``: one dataset's record (as in :meth:`datasets`)."""
        return self._json("GET", f"/datasets/{_quote(dataset_id)}")  # type: ignore[no-any-return]

    def dataset_details(self, dataset_id: str) -> Dict[str, Any]:
        """``GET /datasets/{id}/details``: scale (px/mm), bit depth, frame size and every run's
        frames and commanded move (mm and px)."""
        return self._json("GET", f"/datasets/{_quote(dataset_id)}/details")  # type: ignore[no-any-return]

    def dataset_jobs(self, dataset_id: str) -> List[Dict[str, Any]]:
        """``GET /datasets/{id}/jobs``: the dataset's comparisons, diagnoses and analyses, newest
        first, with their headline figures (``discrepancy_px``, ``verdicts``)."""
        return self._json("GET", f"/datasets/{_quote(dataset_id)}/jobs")  # type: ignore[no-any-return]

    def analyse(
        self, dataset_id: str, *, idempotency_key: Optional[str] = None, **request: Any
    ) -> str:
        """``POST /datasets/{id}/analyses``: queues the study's reductions and DIC on a stored
        dataset (``schemes``, ``dic``; defaults: the paper's; ``card``: a camera card's model
        name, whose distortion and tilt each row's ``card`` takes off) and returns the job id.
        Follow it with ``follow(job, kind="job")``; its study is ``results(job, kind="job")``."""
        return self._submit(f"/datasets/{_quote(dataset_id)}/analyses", request, idempotency_key)

    def compare(
        self,
        dataset_id: str,
        model: str = "baseline",
        *,
        idempotency_key: Optional[str] = None,
        progress: Union[ProgressCallback, bool, None] = None,
        **request: Any,
    ) -> JobResult:
        """``POST /datasets/{id}/comparisons``: the dataset's DIC against the same DIC on frames
        the ``model`` renders; follows the job to its end and returns the comparison
        (``results/comparison.json``: ``dataset``, ``model``, ``discrepancy_px`` and
        ``discrepancy_se_px`` in px, ``parts``, ``runs``, ``images``, ``chi2``). Other request
        fields: ``schemes``, ``dic``, ``seed``. Each comparison joins the dataset's
        :meth:`history`. Raises :class:`RunFailed` if the job fails."""
        body = {"model": model, **request}
        return self._dataset_job(dataset_id, "comparisons", body, idempotency_key, progress)

    def diagnose(
        self,
        dataset_id: str,
        model: str = "baseline",
        rounds: int = 1,
        *,
        idempotency_key: Optional[str] = None,
        progress: Union[ProgressCallback, bool, None] = None,
        **request: Any,
    ) -> JobResult:
        """``POST /datasets/{id}/diagnoses``: fits the effects ``model`` lacks and names the one
        that is missing; follows the job and returns ``results/diagnosis.json`` (``verdict``,
        ``verdicts``, ``discrepancy_px``, ``final_discrepancy_px`` in px, ``candidates``,
        ``ranking_by_drop``, ``rounds`` …). With a verdict, ``result.winner_model_toml`` is the
        model with the effect added (:meth:`add_model` stores it). ``rounds`` > 1 (up to 8) adds
        each winner and diagnoses again, and puts every step into the dataset's history."""
        body = {"model": model, "rounds": rounds, **request}
        return self._dataset_job(dataset_id, "diagnoses", body, idempotency_key, progress)

    def diagnose_on_bench(
        self,
        dataset_id: str,
        model: str = "baseline",
        rounds: int = 1,
        *,
        idempotency_key: Optional[str] = None,
        progress: Union[ProgressCallback, bool, None] = None,
        **request: Any,
    ) -> JobResult:
        """``POST /datasets/{id}/on-bench``: diagnoses the dataset as :meth:`diagnose` does,
        then captures on the daemon's bench the runs that separate what the diagnosis left open
        (its ``runs_to_separate``), appends them to the dataset's runs as a new dataset and
        diagnoses that; follows the job and returns ``results/on-bench.json``: ``before`` and
        ``after`` (diagnoses), ``open_before`` and ``open_after`` (``confounded`` pairs and
        ``not_identifiable`` effects), ``bench`` (``runs``, ``plan``, ``captured`` and
        ``dataset``: the new dataset's id; all null when nothing was left for a bench)."""
        body = {"model": model, "rounds": rounds, **request}
        return self._dataset_job(dataset_id, "on-bench", body, idempotency_key, progress)

    def history(self, dataset_id: str) -> List[Dict[str, Any]]:
        """``GET /datasets/{id}/history``: the dataset's comparisons, oldest first, each with
        ``time``, ``model``, ``version``, ``effects`` and ``discrepancy_px`` (px)."""
        doc = self._json("GET", f"/datasets/{_quote(dataset_id)}/history")
        return list(doc.get("entries", []))

    # --- models -----------------------------------------------------------------------------

    def models(self) -> List[Dict[str, Any]]:
        """``GET /models``: the models a comparison can name (``name``, ``version``,
        ``description``, ``effects``, ``source``: ``embedded`` or ``stored``), baseline first."""
        return self._json("GET", "/models")  # type: ignore[no-any-return]

    def delete_model(self, name: str) -> None:
        """``DELETE /models/{name}``: takes a stored model out of the list (409 for an embedded
        one or while a queued or running run names it). Its name stays its text's: the same
        text may be added again, another may not."""
        self._bytes("DELETE", f"/models/{_quote(name)}")

    def model(self, name: str) -> Dict[str, Any]:
        """``GET /models/{name}``: one model, with its TOML text under ``toml``."""
        return self._json("GET", f"/models/{_quote(name)}")  # type: ignore[no-any-return]

    def add_model(self, toml_text: str) -> Dict[str, Any]:
        """``POST /models`` ``{"toml": toml_text}``: stores a model version (e.g. a diagnosis's
        ``winner_model_toml``) and returns it as :meth:`model` does. The identical model twice
        is fine; another model under a stored or embedded name is a 409, an invalid one a 422
        naming the key."""
        return self._json("POST", "/models", json_body={"toml": toml_text})  # type: ignore[no-any-return]


# --- helpers ----------------------------------------------------------------------------------


def _parse_sse(stream: Any) -> Iterator[Event]:
    """Server-sent events from a binary stream (WHATWG HTML §9.2): ``:`` comments skipped, data
    lines joined with newlines, a blank line dispatching; payloads parsed as JSON when they are."""
    event_id: Optional[int] = None
    name = ""
    data: List[str] = []
    has_data = False
    while True:
        raw = stream.readline()
        if not raw:
            return
        line = raw.decode("utf-8", "replace").rstrip("\r\n")
        if line == "":
            if has_data:
                text = "\n".join(data)
                try:
                    payload: Any = json.loads(text)
                except ValueError:
                    payload = text
                yield Event(event_id, name or "message", payload)
            event_id, name, data, has_data = None, "", [], False
            continue
        if line.startswith(":"):
            continue
        field, sep, value = line.partition(":")
        if sep and value.startswith(" "):
            value = value[1:]
        if field == "data":
            data.append(value)
            has_data = True
        elif field == "event":
            name = value
        elif field == "id":
            try:
                event_id = int(value.strip())
            except ValueError:
                event_id = None


def parse_csv_columns(text: str) -> Dict[str, np.ndarray]:
    """A CSV with a header line as columns: name -> float64 array when every non-empty cell is
    a number (empty cells become NaN), else a numpy string array."""
    rows = list(csv.reader(io.StringIO(text)))
    if not rows:
        return {}
    header, body = rows[0], [r for r in rows[1:] if r]
    columns: Dict[str, np.ndarray] = {}
    for j, name in enumerate(header):
        cells = [r[j] if j < len(r) else "" for r in body]
        try:
            values = [float(c) if c.strip() else float("nan") for c in cells]
        except ValueError:
            columns[name] = np.array(cells, dtype=str)
        else:
            columns[name] = np.array(values, dtype=np.float64)
    return columns


def _multipart(paths: List[Tuple[str, str]]) -> Tuple[Iterator[bytes], int, str]:
    """A multipart/form-data body streamed from files: one part per file, named by its file name.
    Returns the chunks, the total length and the Content-Type with its boundary."""
    boundary = "ffdic-" + uuid.uuid4().hex
    heads: List[bytes] = []
    length = 0
    for name, path in paths:
        ctype = "application/json" if name.endswith(".json") else (
            "image/tiff" if name.lower().endswith((".tif", ".tiff")) else "application/octet-stream"
        )
        quoted = name.replace("\\", "\\\\").replace('"', '\\"')
        head = (
            f"--{boundary}\r\n"
            f'Content-Disposition: form-data; name="{quoted}"; filename="{quoted}"\r\n'
            f"Content-Type: {ctype}\r\n\r\n"
        ).encode("utf-8")
        heads.append(head)
        length += len(head) + os.path.getsize(path) + 2
    tail = f"--{boundary}--\r\n".encode("ascii")
    length += len(tail)

    def chunks() -> Iterator[bytes]:
        for head, (_, path) in zip(heads, paths):
            yield head
            with open(path, "rb") as f:
                while True:
                    block = f.read(1 << 20)
                    if not block:
                        break
                    yield block
            yield b"\r\n"
        yield tail

    return chunks(), length, f"multipart/form-data; boundary={boundary}"


class _ProgressLine:
    """``follow(progress=True)``: one line that updates in place on a terminal, and a line per
    10 % step otherwise (logs stay short)."""

    def __init__(self, run_id: str) -> None:
        self.run_id = run_id
        self.tty = sys.stdout.isatty()
        self.last_step = -1
        self.shown = False

    def __call__(self, fraction: float, event: Event) -> None:
        pct = 100.0 * fraction
        msg = event.message[:60]
        if self.tty:
            sys.stdout.write(f"\r{self.run_id}: {pct:5.1f} %  {msg:<60}")
            sys.stdout.flush()
            self.shown = True
        else:
            step = int(pct // 10)
            if step > self.last_step or event.terminal:
                self.last_step = step
                print(f"{self.run_id}: {pct:5.1f} %  {msg}", flush=True)

    def close(self) -> None:
        if self.tty and self.shown:
            sys.stdout.write("\n")
            sys.stdout.flush()
