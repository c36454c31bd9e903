"""Offline forecasts: the online estimator run over a telemetry file.

:func:`offline_forecasts` feeds every row of recorded telemetry that holds any data, in
time order, to the same :class:`~zonecast.service.online.OnlineEstimator` the service's
runner uses, and returns the forecasts issued at the requested times. A replay of the
same telemetry through MQTT into the service must give the same numbers (the replay
test checks 1e-9).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from pathlib import Path

import pandas as pd

from zonecast.service.modelfile import ModelBundle, load_model_file
from zonecast.service.online import MAX_GAP, Forecast, OnlineEstimator, rows_from_frame

__all__ = ["offline_forecasts", "telemetry_frame"]


def telemetry_frame(telemetry, bundle: ModelBundle) -> pd.DataFrame:
    """Telemetry (a :class:`Telemetry`, a file or folder holding telemetry.csv, or an SI
    frame indexed by UTC time) -> SI frame with one column per site point."""
    from zonecast.estimator.telemetry import Telemetry, load_telemetry

    if isinstance(telemetry, pd.DataFrame):
        return telemetry
    if isinstance(telemetry, Telemetry):
        return telemetry.frame
    path = Path(telemetry)
    return load_telemetry(path / "telemetry.csv" if path.is_dir() else path, bundle.site).frame


def offline_forecasts(model_file, telemetry, times: Iterable, *,
                      max_gap: pd.Timedelta = MAX_GAP,
                      inputs: Mapping | None = None) -> dict[pd.Timestamp, Forecast]:
    """Forecasts issued at ``times`` by the online estimator run over ``telemetry``.

    Parameters
    ----------
    model_file : path or ModelBundle
        Identified-model file (:func:`~zonecast.service.modelfile.load_model_file`).
    telemetry : Telemetry, path or DataFrame
        Recorded telemetry of the site (SI units when a frame).
    times : iterable of tz-aware timestamps
        Issue times; each must be a row of the telemetry with data at or after the
        filter's start.
    max_gap : pandas.Timedelta
        As for :class:`OnlineEstimator`.
    inputs : mapping, optional
        UTC issue time -> (96, n_boxes + 6) inputs over the horizon for
        :meth:`OnlineEstimator.forecast` (default persistence inputs).

    Returns
    -------
    dict
        UTC issue time -> :class:`Forecast`.
    """
    bundle = model_file if isinstance(model_file, ModelBundle) else load_model_file(model_file)
    wanted = set()
    for t in times:
        ts = pd.Timestamp(t)
        if ts.tzinfo is None:
            raise ValueError(f"issue time {t!r} needs a UTC offset")
        wanted.add(ts.tz_convert("UTC"))
    frame = telemetry_frame(telemetry, bundle)
    frame = frame[frame.notna().any(axis=1)]
    est = OnlineEstimator(bundle, max_gap=max_gap)
    out: dict[pd.Timestamp, Forecast] = {}
    last = max(wanted) if wanted else None
    tt, u, v, y = rows_from_frame(bundle, frame)
    for k, t in enumerate(tt):
        if last is not None and t > last:
            break
        est.advance(t, u[k], v[k], y[k])
        if t in wanted and est.started:
            out[t] = est.forecast(None if inputs is None else inputs.get(t))
    missing = sorted(wanted - set(out))
    if missing:
        raise ValueError(f"no forecast at {len(missing)} requested times (first "
                         f"{missing[0].isoformat()}): not a telemetry row with data, or before "
                         "the first measurement")
    return out
