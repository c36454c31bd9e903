"""The state and forecast bodies of a building, shared by the REST routes and the MQTT
publisher of the service (docs/service.md, "REST API" and "MQTT output")."""

from __future__ import annotations

from datetime import UTC, datetime
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd
from fastapi import HTTPException
from zonecast.estimator.constants import STEP_S
from zonecast.estimator.forecast import Forecast
from zonecast.service import schemas as S
from zonecast.service.runner import Runner

if TYPE_CHECKING:  # the context imports this module (it publishes these bodies)
    from zonecast.service.context import ServiceContext

__all__ = ["as_utc", "finite_or_none", "forecast_body", "forecast_json", "state_body"]


def as_utc(t: datetime | pd.Timestamp | None) -> datetime | None:
    """A time as a tz-aware UTC datetime (None stays None)."""
    return None if t is None else pd.Timestamp(t).tz_convert(UTC).to_pydatetime()


def finite_or_none(x: float) -> float | None:
    """``x`` as a float, None if it is not finite (JSON has no NaN)."""
    return float(x) if np.isfinite(x) else None


def state_body(ctx: ServiceContext, runner: Runner) -> S.StateBody:
    """The current state estimate of the runner's building with its quality flags."""
    now = datetime.now(UTC)
    with runner.lock:
        est = runner.est
        zones = []
        flags = []
        if est.started:
            mean, std = est.zone_estimate()
            zones = [S.ZoneState(zone=z, temperature=float(m), std=float(s),
                                 measured=finite_or_none(y))
                     for z, m, s, y in zip(est.bundle.zones, mean, std, est.last_y)]
        else:
            flags.append("not_started")
        rep = runner.last_report
        if rep is not None:
            flags += [f"missing_sensor:{z}" for z in rep.missing_zones]
            flags += [f"held_input:{n}" for n in rep.held_inputs]
        if est.resets:
            flags.append("filter_restarted")
        if not runner.unseen.all():  # once any point was processed: those never seen
            flags += [f"never_received:{p}" for p, u in zip(runner.points, runner.unseen) if u]
        last = est.time
        late, last_late = runner.late_readings, runner.last_late
        tracker = runner.gaps
        open_gaps = tracker.open_gaps()
        flags += [f"gap:{p}" for p, _ in open_gaps]
        gaps = S.GapSummary(open=[S.OpenGap(point=p, since=as_utc(t)) for p, t in open_gaps],
                            found=tracker.gaps_found, missing_steps=tracker.missing_steps,
                            tolerance_s=tracker.tolerance)
        steps, nis = est.steps, (est.nis_sum / est.dof_sum if est.dof_sum else None)
    wm = runner.watermark
    fresh = (now - wm).total_seconds() if wm is not None else None
    age = (now - last).total_seconds() if last is not None else None
    limit = 2 * STEP_S + ctx.settings.runner.grace
    if age is not None and age > limit:
        flags.append("stale")
    if late:
        flags.append("late_readings")
    return S.StateBody(building=runner.building, last_update=as_utc(last),
                       data_freshness_s=fresh, update_age_s=age, zones=zones, steps=steps,
                       nis_per_dof=nis, quality=flags, late_readings=late,
                       late_reading_times=None if last_late is None
                       else [as_utc(last_late[0]), as_utc(last_late[1])], gaps=gaps)


def forecast_body(runner: Runner, steps: int, fc: Forecast | None = None) -> S.ForecastBody:
    """The first ``steps`` steps of ``fc`` (default: the runner's current forecast); 409 with
    :meth:`Runner.forecast_problem` if there is none or it is undefined (an input never
    had a value): never a body of nulls."""
    if fc is None:
        problem = runner.forecast_problem()
        if problem is not None:
            raise HTTPException(409, problem)
        fc = runner.forecast
    sl = slice(0, steps)
    zones = [S.ZoneForecast(zone=z, mean=fc.mean[sl, i].tolist(), lower=fc.lower[sl, i].tolist(),
                            upper=fc.upper[sl, i].tolist(), std=fc.std[sl, i].tolist(),
                            internal_gains=fc.f_ig[sl, i].tolist())
             for i, z in enumerate(fc.zones)]
    return S.ForecastBody(building=runner.building, issued=as_utc(fc.issued),
                          model_version=fc.model_version, step_s=STEP_S,
                          times=[as_utc(t) for t in fc.times[sl]], zones=zones)


def forecast_json(runner: Runner, steps: int) -> bytes:
    """JSON of :func:`forecast_body` for the runner's current forecast, built once per
    forecast and horizon (the REST endpoint and the MQTT publisher serve these bytes);
    409 as :func:`forecast_body` when it cannot be served."""
    problem = runner.forecast_problem()
    if problem is not None:
        raise HTTPException(409, problem)
    fc = runner.forecast
    cached = runner.__dict__.get("_body_cache")
    if cached is None or cached[0] is not fc:  # a new forecast: start a new cache
        cached = (fc, {})
        runner.__dict__["_body_cache"] = cached
    body = cached[1].get(steps)
    if body is None:
        body = forecast_body(runner, steps, fc).model_dump_json().encode()
        cached[1][steps] = body
    return body
