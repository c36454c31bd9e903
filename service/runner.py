"""The online runner of one building: stored readings -> 15-min steps -> state and forecasts.

Row alignment (docs/data.md): the row at grid time t holds the zone temperatures read at
t and the inputs averaged over [t, t + 15 min); readings are stored with their own
timestamps, and a reading belongs to row t when its time is exactly t (BMS samples are
expected on the grid; the REST/MQTT contract says so).

A row t is *closed* (processed, and never again) when the first of these holds:

- every point the site maps has a reading at t (complete), and all earlier rows are closed;
- the watermark (newest reading time stored for the building) has reached
  t + step + grace: later data is flowing, so stragglers of t had ``grace`` to arrive;
- no reading has arrived for ``idle_timeout`` of wall-clock time and the wall clock is
  past t + step + grace (the feed stopped; the last, incomplete row is used as it is).

A closed row with at least one reading goes to the :class:`OnlineEstimator`; a closed
row without any is skipped (the estimator bridges it by prediction). Readings that
arrive for a closed row stay in storage but do not change the past state. The
estimator state and the next row are checkpointed after every processed row, so a
restarted runner resumes exactly there and processes what arrived meanwhile.
"""

from __future__ import annotations

import json
import logging
import threading
import time as _time
from collections import deque
from collections.abc import Callable
from datetime import UTC, datetime

import numpy as np
import pandas as pd
from zonecast.estimator.artifact import ModelBundle
from zonecast.estimator.constants import STEP, STEPS_PER_DAY
from zonecast.estimator.forecast import Forecast
from zonecast.estimator.streaming import (
    OnlineEstimator,
    RowConverter,
    StepReport,
    checkpoint_header,
)
from zonecast.service.settings import RunnerSettings
from zonecast.service.storage import Storage

__all__ = ["Runner", "read_checkpoint"]

log = logging.getLogger(__name__)
#: envelope of the checkpoints written before the estimator's header carried the runner's
#: next row (read, never written)
_LEGACY_MAGIC = b"ZCR1"


def read_checkpoint(data: bytes) -> tuple[dict, bytes]:
    """A stored checkpoint -> (header with ``version`` and ``next_time``, estimator state).

    One envelope: the estimator's own (:meth:`OnlineEstimator.to_bytes`) with the runner's
    next row in its ``extra``; the runner envelope of earlier versions still loads.
    """
    if data[:4] == _LEGACY_MAGIC:
        n = int.from_bytes(data[4:8], "big")
        return json.loads(data[8:8 + n]), data[8 + n:]
    head = checkpoint_header(data)
    return {"version": head.get("version"), **head.get("extra", {})}, data


class Runner:
    """Keep one building's state current from its stored readings.

    Parameters
    ----------
    bundle : ModelBundle
    storage : Storage
    settings : RunnerSettings
    clock : callable, optional
        Returns the current UTC time (tests pass a fake one).
    publish : callable(kind, runner), optional
        Called after each processed row (kind ``"state"``) and each forecast
        (``"forecast"``); the app publishes them over MQTT.
    """

    def __init__(self, bundle: ModelBundle, storage: Storage, settings: RunnerSettings, *,
                 clock: Callable[[], datetime] = lambda: datetime.now(UTC),
                 publish: Callable[[str, Runner], None] | None = None):
        self.bundle = bundle
        self.building = bundle.building
        self.storage = storage
        self.settings = settings
        self.clock = clock
        self.publish = publish
        self.units = bundle.site.point_units()
        self.convert = RowConverter(bundle)
        self.points = self.convert.points
        self.est = OnlineEstimator(bundle, max_gap=pd.Timedelta(seconds=settings.max_gap))
        self.next_time: pd.Timestamp | None = None
        self.forecast: Forecast | None = None
        self.history: deque[Forecast] = deque(maxlen=1024)
        self.last_report: StepReport | None = None
        self.latencies: deque[float] = deque(maxlen=10000)
        self.lock = threading.RLock()
        self.errors = 0
        self.last_error: str | None = None
        self.watermark: datetime | None = None
        self._grace = pd.Timedelta(seconds=settings.grace)
        self._resume()

    # --- checkpoint ------------------------------------------------------------------
    def _resume(self) -> None:
        cp = self.storage.load_checkpoint(self.building)
        if cp is None:
            return
        meta, blob = read_checkpoint(cp.state)
        if meta.get("version") != self.bundle.version:
            log.warning("building %s: checkpoint of model %s, now %s: starting the filter "
                        "afresh from the checkpoint's next row", self.building,
                        meta.get("version"), self.bundle.version)
        else:
            self.est.load_bytes(blob)
            if self.est.started:
                self.forecast = self.est.forecast()
        self.next_time = pd.Timestamp(meta["next_time"]) if meta.get("next_time") else None
        log.info("building %s: resumed at %s", self.building, self.next_time)

    def _checkpoint(self) -> None:
        extra = {"next_time": None if self.next_time is None else self.next_time.isoformat()}
        # not synced to disk per step: if a power cut loses it, the rows after the
        # previous one are recomputed from readings committed (synced) before them
        self.storage.save_checkpoint(self.building, self.est.time or self.next_time,
                                     self.est.to_bytes(extra), sync=False)

    # --- stepping ----------------------------------------------------------------------
    def poll(self) -> int:
        """Process every row that can be closed now; returns how many were processed."""
        done = 0
        while True:
            first, last, received = self.storage.reading_bounds(self.building, self.next_time)
            self.watermark = last
            if first is None or last is None:
                return done
            first = pd.Timestamp(first).floor(STEP)
            if self.next_time is None or first > self.next_time + STEPS_PER_DAY * STEP:
                self.next_time = first  # start, or a day without any data: jump
            n, more = self._poll_chunk(pd.Timestamp(last), pd.Timestamp(received))
            done += n
            if not more:
                return done

    def _poll_chunk(self, watermark: pd.Timestamp, received: pd.Timestamp) -> tuple[int, bool]:
        start = self.next_time
        end = min(start + STEPS_PER_DAY * STEP, watermark.floor(STEP) + STEP)
        times, values = self.storage.readings_matrix(self.building, start, end, self.points)
        rows = dict(zip(times.tolist(), values))
        now = pd.Timestamp(self.clock())
        idle = (now - received).total_seconds() >= self.settings.idle_timeout
        done = 0
        t = start
        while t < end:
            row = rows.get(t.value)
            present = None if row is None else np.isfinite(row)
            complete = present is not None and bool(present.all())
            closable = (complete or watermark >= t + STEP + self._grace
                        or (idle and now >= t + STEP + self._grace))
            if not closable:
                return done, False
            self.next_time = t + STEP
            if present is not None and present.any():
                self._process(t, row)
                done += 1
            t += STEP
        return done, end <= watermark

    def _process(self, t: pd.Timestamp, row: np.ndarray) -> None:
        """One row: ``row`` holds the readings of :attr:`points` at ``t`` in their wire
        units (NaN = none)."""
        t0 = _time.perf_counter()
        u, v, y = self.convert.convert(np.array([t.value], dtype=np.int64), row[None, :])
        every = self.settings.forecast_every
        with self.lock:
            report = self.est.advance(t, u[0], v[0], y[0])
            if report is not None:
                self.last_report = report
            issue = self.est.started and (t.value // STEP.value) % every == 0
            if issue:
                self.forecast = self.est.forecast()
                self.history.append(self.forecast)
            self._checkpoint()
        self.latencies.append(_time.perf_counter() - t0)
        if self.publish is not None:
            try:
                self.publish("state", self)
                if issue:
                    self.publish("forecast", self)
            except Exception:  # publishing is best effort; the state is stored
                log.exception("building %s: publishing failed", self.building)

    # --- background loop ------------------------------------------------------------------
    def run(self, stop: threading.Event) -> None:
        """Poll until ``stop`` is set (the app runs this in a thread)."""
        while not stop.is_set():
            try:
                self.poll()
            except Exception as exc:  # keep running; the next poll retries from storage
                self.errors += 1
                self.last_error = str(exc)
                log.exception("building %s: runner step failed", self.building)
            stop.wait(self.settings.poll_interval)
