"""The last hours of a building as the operator sees them: the window of grid times, the
measured zone temperatures, readings missing per point and the filter's innovations
(read-only; used by ``/history``, ``/health`` and the operator page ``/ui``)."""

from __future__ import annotations

import numpy as np
import pandas as pd
from zonecast.estimator.constants import STEP, STEP_S
from zonecast.service.runner import Runner

__all__ = ["innovation_rms", "missing_per_point", "window", "zone_history"]


def window(runner: Runner, hours: int) -> pd.DatetimeIndex:
    """Grid times of the ``hours`` [h] ending at the runner's last processed step (else at
    the newest stored reading); empty when neither exists."""
    with runner.lock:
        end = runner.est.time
    if end is None:
        _, last, _ = runner.storage.reading_bounds(runner.building)
        if last is None:
            return pd.DatetimeIndex([], tz="UTC")
        end = pd.Timestamp(last).floor(STEP)
    n = int(hours * 3600 // STEP_S)
    return pd.date_range(end=pd.Timestamp(end).tz_convert("UTC"), periods=n, freq=STEP)


def _rows(times: pd.DatetimeIndex, stamps: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Row of each stored time in ``times`` and which stored times are on it."""
    grid = times.as_unit("ns").asi8
    rows = grid.searchsorted(stamps)
    on = (rows < len(grid)) & (grid[np.minimum(rows, len(grid) - 1)] == stamps)
    return rows, on


def zone_history(runner: Runner, times: pd.DatetimeIndex) -> np.ndarray:
    """Measured zone temperatures y [degC] at ``times`` (rows) per zone (columns), NaN
    where no sensor of the zone reported: the stored readings converted as the runner
    converts them (:meth:`~zonecast.estimator.streaming.RowConverter.zone_temperatures`)."""
    y = np.full((len(times), len(runner.bundle.zones)), np.nan)
    if not len(times):
        return y
    conv = runner.convert
    stamps, values = runner.storage.readings_matrix(runner.building, times[0],
                                                    times[-1] + STEP, conv.zone_points)
    rows, on = _rows(times, stamps)
    if on.any():
        y[rows[on]] = conv.zone_temperatures(values[on])
    return y


def missing_per_point(runner: Runner, times: pd.DatetimeIndex) -> dict[str, int]:
    """Point -> grid times of ``times`` without a stored reading of it [-] (every point of
    the site, zeros included)."""
    points = runner.points
    if not len(times):
        return dict.fromkeys(points, 0)
    stamps, values = runner.storage.readings_matrix(runner.building, times[0],
                                                    times[-1] + STEP, points)
    _, on = _rows(times, stamps)
    present = np.isfinite(values[on]).sum(axis=0)
    return {p: int(len(times) - n) for p, n in zip(points, present)}


def innovation_rms(runner: Runner, since: pd.Timestamp | None) -> tuple[np.ndarray, np.ndarray]:
    """RMS of the innovations per zone [K] of the processed steps at or after ``since``
    that the runner holds in memory (NaN without any), and their number per zone."""
    with runner.lock:
        kept = [v for t, v in runner.innovations if since is None or t >= since]
    nz = len(runner.bundle.zones)
    if not kept:
        return np.full(nz, np.nan), np.zeros(nz, dtype=int)
    inn = np.array(kept)
    n = np.isfinite(inn).sum(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        rms = np.sqrt(np.nansum(inn ** 2, axis=0) / n)
    return np.where(n > 0, rms, np.nan), n
