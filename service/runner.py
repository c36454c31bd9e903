"""The online runner of one building: stored readings -> 15-min steps -> state and forecasts.

Row alignment (docs/data.md): the row at grid time t holds the zone temperatures read at
t and the inputs averaged over [t, t + 15 min); readings are stored with their own
timestamps, and a reading belongs to row t when its time is exactly t (BMS samples are
expected on the grid; the REST/MQTT contract says so).

A row t is *closed* (processed, and never again) when the first of these holds:

- every point the site maps has a reading at t (complete), and all earlier rows are closed;
- the watermark has reached t + step + grace: later data is flowing, so stragglers of t
  had ``grace`` to arrive. The watermark is the newest time at which at least
  ``watermark_support`` (default 2) points have readings: one reading stamped far ahead of
  the stream (a publisher with a wrong clock) does not move it;
- no reading has arrived for ``idle_timeout`` of wall-clock time and the wall clock is
  past t + step + grace (the feed stopped; the last, incomplete row is used as it is).

A closed row with at least one reading goes to the :class:`OnlineEstimator`; a closed
row without any is skipped (the estimator bridges it by prediction). The runner starts at
the oldest stored reading, and after a day without data jumps to the next reading, only
when the watermark has reached that reading (or the feed is idle): a lone reading ahead of
the stream can neither start the runner nor pull it over the data in between.

Readings outside [1970, wall clock + 1 day) never reach the runner (ingest already refuses
them; this guards what was stored before). Readings that arrive for a closed row stay in
storage but do not change the past state; they are counted (:attr:`Runner.late_readings`,
``/state``, ``/metrics``) and logged, never ignored silently. The estimator state and the
next row are checkpointed after every processed row, so a restarted runner resumes
exactly there and processes what arrived meanwhile.
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
from zonecast.service.gaps import GapTracker
from zonecast.service.settings import RunnerSettings
from zonecast.service.storage import Storage

__all__ = ["Runner", "read_checkpoint"]

log = logging.getLogger(__name__)
#: envelope of the checkpoints written before the estimator's header carried the runner's
#: next row (read, never written)
_LEGACY_MAGIC = b"ZCR1"
#: readings before this never reach the runner (pandas' nanosecond times end in 1677 and
#: 2262; ingest refuses such times, this guards data stored before that rule)
EARLIEST = pd.Timestamp("1970-01-01", tz="UTC")
#: nor readings further ahead of the wall clock than this
FUTURE_GUARD = pd.Timedelta(days=1)


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
        #: every point of the site (gaps, never-received): the estimator's and the lights
        #: and plug-load meters, which are stored for the identification but which no row
        #: waits for and which alone do not make a row (``_est``: the estimator's columns)
        self.points = list(self.units)
        col = {p: i for i, p in enumerate(self.points)}
        self._est = np.array([col[p] for p in self.convert.points], dtype=int)
        self.est = OnlineEstimator(bundle, max_gap=pd.Timedelta(seconds=settings.max_gap))
        self.est.reheat_control = settings.thermostat_forecast
        self.next_time: pd.Timestamp | None = None
        #: the filter's time right after the checkpoint was loaded (None: none loaded)
        self.resumed_from: pd.Timestamp | None = None
        self.forecast: Forecast | None = None
        self.history: deque[Forecast] = deque(maxlen=1024)
        self.last_report: StepReport | None = None
        #: (row time, innovation per zone [K]) of the last two days of processed rows, in
        #: memory only (empty after a restart): the model health of /health and /ui
        self.innovations: deque[tuple[pd.Timestamp, np.ndarray]] = deque(
            maxlen=2 * STEPS_PER_DAY)
        self.latencies: deque[float] = deque(maxlen=10000)
        self.lock = threading.RLock()
        self.errors = 0
        self.last_error: str | None = None
        self.watermark: datetime | None = None
        #: readings that arrived for rows already processed (not used), and the span of
        #: their times, since the runner started
        self.late_readings = 0
        self.last_late: tuple[datetime, datetime] | None = None
        self._grace = pd.Timedelta(seconds=settings.grace)
        self._support = min(settings.watermark_support, len(self._est))
        #: points whose readings do not move the watermark: the meters, which no row waits
        #: for (a meter feed ahead of the temperatures would otherwise close their rows)
        self._not_watermark = sorted(set(self.points) - set(self.convert.points))
        # points without any reading in a processed row yet (named by /forecast's 409)
        self.unseen = np.ones(len(self.points), dtype=bool)
        self._received_seen: datetime | None = None  # arrivals checked for late readings
        self._forecast_ok = False
        self._undefined_from: pd.Timestamp | None = None
        #: gaps in the site's points, found as rows close (service/gaps.py)
        self.gaps = GapTracker(self.building, self.points, storage,
                               tolerance=settings.gap_tolerance)
        self._resume()
        self.gaps.resume(self.next_time)

    # --- checkpoint ------------------------------------------------------------------
    def _resume(self) -> None:
        cp = self.storage.load_checkpoint(self.building)
        if cp is None:
            log.info("building %s: runner started without a checkpoint (first step at the "
                     "oldest stored reading)", self.building,
                     extra={"building": self.building, "model_version": self.bundle.version})
            return
        meta, blob = read_checkpoint(cp.state)
        if meta.get("version") != self.bundle.version:
            log.warning("building %s: checkpoint of model %s, now %s: starting the filter "
                        "afresh from the checkpoint's next row", self.building,
                        meta.get("version"), self.bundle.version,
                        extra={"building": self.building})
        else:
            try:
                self.est.load_bytes(blob)
            except ValueError as exc:  # another layout of the same model's rows
                log.warning("building %s: checkpoint not loaded (%s): starting the filter "
                            "afresh from the checkpoint's next row", self.building, exc,
                            extra={"building": self.building})
                self.est.reset()
            if self.est.started:
                self._set_forecast(self.est.forecast())
        self.next_time = pd.Timestamp(meta["next_time"]) if meta.get("next_time") else None
        #: the filter's time right after loading the checkpoint (None: no state loaded)
        self.resumed_from = self.est.time if self.est.started else None
        # checkpoints before "unseen" was kept say nothing: take every point as seen
        unseen = set(meta.get("unseen", ()))
        self.unseen = np.array([p in unseen for p in self.points], dtype=bool)
        # readings that arrive after this checkpoint for rows before next_time are late
        self._received_seen = cp.saved_at
        log.info("building %s: resumed at %s", self.building, self.next_time,
                 extra={"building": self.building, "next_row": str(self.next_time),
                        "model_version": self.bundle.version})

    def _set_forecast(self, fc: Forecast) -> None:
        self.forecast = fc
        bad = ~np.isfinite(fc.mean).all(axis=1)
        self._forecast_ok = not bad.any()
        self._undefined_from = None if self._forecast_ok else fc.times[int(np.argmax(bad))]

    def forecast_problem(self) -> str | None:
        """Why the current forecast cannot be served (None if it can): no forecast yet
        (the filter has not started), or one with undefined values because an input has
        never had a value; the text names the points without any reading so far."""
        never = [p for p, u in zip(self.points, self.unseen) if u]
        named = f"; points never received: {never}" if never else ""
        if self.forecast is None:
            if not self.est.started:
                return (f"no forecast for building {self.building!r}: the filter has not "
                        f"started (no zone temperature processed yet){named}")
            return f"no forecast for building {self.building!r} yet"
        if not self._forecast_ok:
            rep = self.last_report
            held = (f"; inputs without a value in the last row: {rep.held_inputs}"
                    if rep is not None and rep.held_inputs else "")
            return (f"the forecast of building {self.building!r} issued at "
                    f"{self.forecast.issued.isoformat()} is undefined from "
                    f"{self._undefined_from.isoformat()} on: an input had no value in the row "
                    f"it persists (inputs of the last 24 h) or has never had one{held}{named}")
        return None

    def _checkpoint(self) -> None:
        extra = {"next_time": None if self.next_time is None else self.next_time.isoformat(),
                 "unseen": [p for p, u in zip(self.points, self.unseen) if u]}
        # not synced to disk per step: if a power cut loses it, the rows after the
        # previous one are recomputed from readings committed (synced) before them
        self.storage.save_checkpoint(self.building, self.est.time or self.next_time,
                                     self.est.to_bytes(extra), sync=False)

    # --- weather forecasts ---------------------------------------------------------------
    def set_weather_forecast(self, wf) -> bool:
        """Use the weather forecast ``wf`` (:class:`~zonecast.estimator.weather_forecast.
        WeatherForecast`) from the next processed row on, unless the one in use was issued
        later; it is checkpointed at once. Returns whether it was taken."""
        with self.lock:
            cur = self.est.weather
            if cur is not None and cur.issued > wf.issued:
                return False
            self.est.set_weather_forecast(wf)
            if self.est.time is not None or self.next_time is not None:
                self._checkpoint()
        log.info("building %s: weather forecast issued %s (%s, %d values) in use",
                 self.building, wf.issued.isoformat(), wf.source or "no source",
                 len(wf.times), extra={"building": self.building})
        return True

    # --- stepping ----------------------------------------------------------------------
    def poll(self) -> int:
        """Process every row that can be closed now; returns how many were processed."""
        done = 0
        while True:
            now = pd.Timestamp(self.clock())
            until = now + FUTURE_GUARD
            since = EARLIEST if self.next_time is None else max(self.next_time, EARLIEST)
            first, last, received = self.storage.reading_bounds(self.building, since, until)
            self.watermark = last
            if received is not None:
                self._count_late(received)
            if first is None or last is None:
                return done
            first = pd.Timestamp(first).floor(STEP)
            support = self.storage.supported_watermark(self.building, since, until,
                                                       self._support,
                                                       exclude=self._not_watermark)
            support = None if support is None else pd.Timestamp(support)
            idle = (now - pd.Timestamp(received)).total_seconds() >= self.settings.idle_timeout
            if self.next_time is None or first > self.next_time + STEPS_PER_DAY * STEP:
                # start, or a day without any data: jump to the next reading, but only to
                # one the watermark has reached (or once the feed is idle)
                if (support is not None and first <= support) \
                        or (idle and now >= first + STEP + self._grace):
                    self.next_time = first
                elif self.next_time is None:
                    return done
            n, more = self._poll_chunk(support, pd.Timestamp(last), now, idle)
            done += n
            if not more:
                return done

    def _count_late(self, received: datetime) -> None:
        """Count the readings that arrived since the last look for rows already closed."""
        seen = self._received_seen
        if seen is not None and received > seen and self.next_time is not None:
            n, lo, hi = self.storage.late_readings(self.building, seen, received,
                                                   self.next_time)
            if n:
                self.late_readings += n
                self.last_late = (lo, hi)
                log.warning("building %s: %d readings arrived for rows already processed "
                            "(times %s to %s); they are stored but not used", self.building,
                            n, lo.isoformat(), hi.isoformat(),
                            extra={"building": self.building, "reason": "late_reading",
                                   "count": n, "first": lo.isoformat(),
                                   "last": hi.isoformat()})
        if seen is None or received > seen:
            self._received_seen = received

    def _poll_chunk(self, support: pd.Timestamp | None, last: pd.Timestamp,
                    now: pd.Timestamp, idle: bool) -> tuple[int, bool]:
        start = self.next_time
        end = min(start + STEPS_PER_DAY * STEP, last.floor(STEP) + STEP)
        times, values = self.storage.readings_matrix(self.building, start, end, self.points)
        rows = dict(zip(times.tolist(), values))
        done = 0
        t = start
        while t < end:
            row = rows.get(t.value)
            present = None if row is None else np.isfinite(row)
            complete = present is not None and bool(present[self._est].all())
            closable = (complete or (support is not None and support >= t + STEP + self._grace)
                        or (idle and now >= t + STEP + self._grace))
            if not closable:
                self._chunk_done(done)
                return done, False
            # under the lock: a checkpoint taken meanwhile by another thread (a new weather
            # forecast) sees the next row and the state of the rows before it, never the
            # next row advanced past a row not yet in the state
            issue = None
            with self.lock:
                self.next_time = t + STEP
                self.gaps.observe(t, present)
                if present is not None and present[self._est].any():
                    self.unseen &= ~present
                    issue = self._process(t, row[self._est])
                    done += 1
                elif present is not None:
                    self.unseen &= ~present
            if issue is not None:
                self._publish_row(issue)  # outside the lock, as the API reads under it
            t += STEP
        self._chunk_done(done)
        return done, end <= last

    def _chunk_done(self, done: int) -> None:
        """Checkpoint once at the end of a chunk of closed rows (at most a day of them; live,
        one row). A crash inside a chunk loses those rows' progress only: the restarted
        runner recomputes them from the stored readings and reaches the same state."""
        if done:
            with self.lock:
                self._checkpoint()

    def _process(self, t: pd.Timestamp, row: np.ndarray) -> bool:
        """One row: ``row`` holds the readings of the estimator's points
        (``convert.points``) at ``t`` in their wire units (NaN = none). Returns whether a
        forecast was issued (for :meth:`_publish_row`)."""
        t0 = _time.perf_counter()
        u, v, y, rh = self.convert.convert_rows(np.array([t.value], dtype=np.int64),
                                                row[None, :])
        every = self.settings.forecast_every
        with self.lock:
            report = self.est.advance(t, u[0], v[0], y[0], rh[0])
            if report is not None:
                self.last_report = report
                if report.innovation is not None:
                    self.innovations.append((report.time, report.innovation))
            issue = self.est.started and (t.value // STEP.value) % every == 0
            if issue:
                self._set_forecast(self.est.forecast())
                self.history.append(self.forecast)
        self.latencies.append(_time.perf_counter() - t0)
        return issue

    def _publish_row(self, issue: bool) -> None:
        """Publish the state after a processed row, and the forecast if one was issued."""
        if self.publish is not None:
            try:
                self.publish("state", self)
                if issue and self._forecast_ok:  # an undefined forecast is not published
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
