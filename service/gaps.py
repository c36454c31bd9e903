"""Gaps in the telemetry a building's site declares: per point, runs of 15-min steps that
the runner closed without a reading of that point.

The runner feeds every row it closes to :meth:`GapTracker.observe` (its time and which
points had a reading), in time order, so gaps are found incrementally as the runner
advances: no request and no restart rescans the history. Rows the runner jumped over (a
day without any data) are missing for every point. A run of missing steps longer than the
tolerance (``RunnerSettings.gap_tolerance``) is a *gap*: written to storage when it opens
and again when it closes (``Storage.record_gaps``, table ``gaps``), counted, and reported
by ``/state``, ``/metrics`` and ``GET /api/v1/buildings/{id}/gaps``.

Where gaps come from: a publisher that stopped sending a point, a broker that dropped
messages (a full queue), a replay that skipped rows. A reading that arrives after its row
was closed does not shorten a gap: the runner did not use it (it is reported as a late
reading instead).
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Sequence

import numpy as np
import pandas as pd
from zonecast.estimator.constants import STEP
from zonecast.service.storage import Gap, Storage

__all__ = ["GapTracker"]

log = logging.getLogger(__name__)


class GapTracker:
    """Find and record one building's gaps as its runner closes rows.

    Parameters
    ----------
    building : str
    points : sequence of str
        The points the site declares (the runner's row columns).
    storage : Storage
        Where gaps are recorded; open gaps are read back on creation, so a restarted
        runner continues them.
    tolerance : float
        Runs of missing steps up to this long are not gaps [s]; 0 (default) makes every
        missing step one.
    """

    def __init__(self, building: str, points: Sequence[str], storage: Storage, *,
                 tolerance: float = 0.0):
        self.building = building
        self.points = list(points)
        self.storage = storage
        self.tolerance = float(tolerance)
        #: a run of more than this many missing steps is a gap
        self.tolerance_steps = int(self.tolerance // STEP.total_seconds())
        self._index = {p: i for i, p in enumerate(self.points)}
        #: per point, the first step of its current run of missing steps (None: not missing)
        self._run: list[pd.Timestamp | None] = [None] * len(self.points)
        self._recorded = np.zeros(len(self.points), dtype=bool)  # the run is a stored gap
        self._last: pd.Timestamp | None = None  # the last closed row
        self._lock = threading.Lock()
        #: since this tracker was created: gaps found (crossed the tolerance) and
        #: point-steps without a reading
        self.gaps_found = 0
        self.missing_steps = 0

    def resume(self, next_time: pd.Timestamp | None) -> None:
        """Continue after the runner's checkpoint: ``next_time`` is its next row. Open gaps
        stored before it are continued; any stored after it belong to rows the runner will
        close again and are found again (same key: overwritten)."""
        with self._lock:
            self._last = None if next_time is None else next_time - STEP
            if next_time is None:
                return
            total, _ = self.storage.gaps(self.building, open_only=True, limit=1)
            if not total:
                return
            _, stored = self.storage.gaps(self.building, open_only=True, limit=total)
            for gap in stored:
                i = self._index.get(gap.point)
                start = pd.Timestamp(gap.start)
                if i is not None and start < next_time:
                    self._run[i] = start
                    self._recorded[i] = True

    def observe(self, t: pd.Timestamp, present: np.ndarray | None) -> None:
        """Row ``t`` was closed; ``present[i]`` tells whether point i had a reading (None:
        no reading at all). Rows must come in time order; a row at or before the last one
        is ignored."""
        writes: list[Gap] = []
        with self._lock:
            last = self._last
            if last is not None and t <= last:
                return
            n = len(self.points)
            if last is not None and t > last + STEP:  # rows jumped over: nothing in them
                skipped = int((t - last) / STEP) - 1
                self.missing_steps += skipped * n
                for i in range(n):
                    if self._run[i] is None:
                        self._run[i] = last + STEP
                    self._note(i, t, writes)  # a run that is a gap already before row t
            have = np.zeros(n, dtype=bool) if present is None else np.asarray(present, bool)
            end = t + STEP
            for i in range(n):
                start = self._run[i]
                if have[i]:
                    if start is not None:
                        if self._recorded[i]:
                            writes.append(Gap(self.points[i], start, t, False))
                        self._run[i] = None
                        self._recorded[i] = False
                    continue
                self.missing_steps += 1
                if start is None:
                    self._run[i] = t
                self._note(i, end, writes)
            self._last = t
        if writes:
            # like the checkpoint, not synced per row: after a power cut the runner resumes
            # from an older checkpoint and finds the same gaps again
            self.storage.record_gaps(self.building, writes, sync=False)
            opened = [g.point for g in writes if g.open]
            if opened:
                since = min(g.start for g in writes if g.open)
                log.warning("building %s: no reading of %d points since %s (%s)",
                            self.building, len(opened), since.isoformat(),
                            ", ".join(opened[:10]) + (" ..." if len(opened) > 10 else ""),
                            extra={"building": self.building, "reason": "gap",
                                   "count": len(opened), "points": opened[:10]})

    def _note(self, i: int, end: pd.Timestamp, writes: list[Gap]) -> None:
        """Record point i's run of missing steps, [start, end), as an open gap once it is
        longer than the tolerance (lock held)."""
        start = self._run[i]
        if not self._recorded[i] and (end - start) / STEP > self.tolerance_steps:
            self._recorded[i] = True
            self.gaps_found += 1
            writes.append(Gap(self.points[i], start, end, True))

    @property
    def position(self) -> pd.Timestamp | None:
        """The first row not closed yet: where an open gap is known to reach."""
        last = self._last
        return None if last is None else last + STEP

    def open_gaps(self) -> list[tuple[str, pd.Timestamp]]:
        """(point, first missing step) of every gap still open."""
        with self._lock:
            return [(p, s) for p, s, r in zip(self.points, self._run, self._recorded)
                    if s is not None and r]
