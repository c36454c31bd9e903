"""The last hours of a building as the operator sees them: the window of grid times, the
measured zone temperatures, readings missing per point and the filter's innovations
(read-only; used by ``/history``, ``/health`` and the operator page ``/ui``)."""

from __future__ import annotations

import numpy as np
import pandas as pd
from zonecast.estimator.constants import STEP, STEP_S
from zonecast.service.runner import Runner

__all__ = ["innovation_rms", "missing_per_point", "readings", "window", "zone_history"]


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


def readings(runner: Runner, times: pd.DatetimeIndex, points: list[str]) -> np.ndarray:
    """Stored readings of ``points`` (wire units) at the grid ``times``: shape
    (len(times), len(points)), NaN where there is none (one storage read)."""
    out = np.full((len(times), len(points)), np.nan)
    if not len(times):
        return out
    stamps, values = runner.storage.readings_matrix(runner.building, times[0],
                                                    times[-1] + STEP, points)
    grid = times.as_unit("ns").asi8
    rows = grid.searchsorted(stamps)
    on = (rows < len(grid)) & (grid[np.minimum(rows, len(grid) - 1)] == stamps)
    out[rows[on]] = values[on]
    return out


def zone_history(runner: Runner, times: pd.DatetimeIndex,
                 all_points: np.ndarray | None = None) -> np.ndarray:
    """Measured zone temperatures y [degC] at ``times`` (rows) per zone (columns), NaN
    where no sensor of the zone reported: the stored readings converted as the runner
    converts them (:meth:`~zonecast.estimator.streaming.RowConverter.zone_temperatures`).
    ``all_points``: the :func:`readings` of every point of the site, if already read."""
    conv = runner.convert
    if all_points is None:
        zone = readings(runner, times, conv.zone_points)
    else:
        col = {p: j for j, p in enumerate(runner.points)}
        zone = all_points[:, [col[p] for p in conv.zone_points]]
    return conv.zone_temperatures(zone)


def missing_per_point(runner: Runner, all_points: np.ndarray) -> dict[str, int]:
    """Point -> grid times without a reading of it [-], from the :func:`readings` of every
    point of the site (zeros included)."""
    return {p: int(n) for p, n in zip(runner.points, np.isnan(all_points).sum(axis=0))}


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
