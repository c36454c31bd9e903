"""Synthetic weather forecasts for a virtual building: the weather it was simulated with,
plus seeded forecast error growing with lead time.

A real site receives numerical weather forecasts (e.g. Open-Meteo); the virtual building
has only its weather file. To score the served forecast with *realistic* weather input,
:func:`weather_forecasts` issues a forecast every ``every`` (default 6 h, like the
cycles of a weather model) reaching ``hours`` ahead (default 36 h), on an hourly grid:

- truth: the campaign's own outdoor temperature at each hour, and the hour's mean of
  GHI, DNI and DHI (the telemetry rows of [hour - 30 min, hour + 30 min));
- temperature error, additive: e(k) = sigma_T(k) eta(k) at lead k [h], with
  sigma_T(k) = 0.3 + 1.7 k / 24 K (0.3 K at issue, 2.0 K at 24 h, ~0.07 K/h) and eta a
  unit-variance AR(1) over the leads with correlation 0.9 per hour;
- irradiance error, multiplicative and the same factor for GHI, DNI and DHI (a cloud-cover
  error): x_f = x max(0, 1 + sigma_I(k) xi(k)), sigma_I(k) = 0.10 + 0.25 k / 24 (0.35 at
  24 h), xi a unit-variance AR(1) with correlation 0.8 per hour; capped at
  1300 / 1100 / 800 W/m2 (GHI / DNI / DHI);
- every issue draws from ``numpy.random.default_rng([seed, 31, issue seconds])``, so a
  forecast does not depend on which others were asked for.

A forecast stops where the telemetry does (the campaign's weeks are not contiguous); one
reaching less than ``min_hours`` is not issued. The output is the weather-forecast body of
docs/data.md, ready for ``POST .../weather_forecast``.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
from zonecast.estimator.site import Site, load_site
from zonecast.estimator.telemetry import load_telemetry

__all__ = ["ERROR_MODEL", "weather_forecasts", "write_weather_forecasts"]

#: the error model (module docstring), recorded with every set of forecasts
ERROR_MODEL = {"temperature_sigma_k": [0.3, 2.0], "temperature_rho_per_h": 0.9,
               "irradiance_sigma": [0.10, 0.35], "irradiance_rho_per_h": 0.8,
               "at_lead_h": [0, 24]}


def _ar1(rng: np.random.Generator, n: int, rho: float) -> np.ndarray:
    """Unit-variance AR(1) series of length n."""
    out = np.empty(n)
    out[0] = rng.standard_normal()
    s = np.sqrt(1.0 - rho ** 2)
    for k in range(1, n):
        out[k] = rho * out[k - 1] + s * rng.standard_normal()
    return out


def weather_forecasts(site: Site, frame: pd.DataFrame, *, seed: int = 0, every: str = "6h",
                      hours: int = 36, min_hours: int = 24,
                      temperature_sigma: tuple[float, float] = (0.3, 2.0),
                      irradiance_sigma: tuple[float, float] = (0.10, 0.35)) -> list[dict]:
    """Synthetic forecasts over the span of ``frame`` (SI telemetry indexed by UTC time).

    Parameters
    ----------
    site : Site
    frame : DataFrame
        Telemetry in SI units, one column per point (``load_telemetry(...).frame``).
    seed : int
        Seed of the errors.
    every : str
        Issue interval (UTC multiples).
    hours : int
        Hours ahead of each forecast [h].
    min_hours : int
        Shortest forecast issued [h].
    temperature_sigma, irradiance_sigma : (float, float)
        Error standard deviations at lead 0 and 24 h (linear in between): temperature [K],
        irradiance factor [-]; the defaults are :data:`ERROR_MODEL`'s, (0, 0) gives the
        weather itself (the same random draws, so one part can be switched off alone).

    Returns
    -------
    list of dict
        Weather-forecast bodies (docs/data.md), in issue order.
    """
    pts = site.points
    cols = [pts.outdoor_air_temperature.point, pts.solar.global_horizontal.point,
            pts.solar.direct_normal.point, pts.solar.diffuse_horizontal.point]
    w = frame[cols].astype(float)
    step = pd.Timedelta(site.step)
    # hourly truth: temperature at the hour, irradiance the mean of [h - 30 min, h + 30 min)
    per_hour = int(pd.Timedelta("1h") / step)
    shifted = w.iloc[:, 1:].copy()
    shifted.index = shifted.index + pd.Timedelta("30min")  # row t covers [t, t + step)
    # shifted row times in [h, h + 1 h) <=> rows of [h - 30 min, h + 30 min)
    rad = shifted.resample("1h").mean()
    counts = shifted.resample("1h").count()
    rad = rad.where(counts.min(axis=1) >= per_hour)
    temp = w.iloc[:, 0]
    temp = temp[temp.index == temp.index.floor("1h")]
    hourly = pd.concat([temp.rename("t"), rad.set_axis(["ghi", "dni", "dhi"], axis=1)],
                       axis=1).sort_index()
    ok = hourly.notna().all(axis=1)
    start = w.index[0].ceil(every)
    issues = pd.date_range(start, w.index[-1], freq=every)
    out = []
    for s in issues:
        hours_idx = pd.date_range(s, periods=hours + 1, freq="1h")
        good = ok.reindex(hours_idx, fill_value=False).to_numpy()
        n = len(good) if good.all() else int(np.argmin(good))
        if n - 1 < min_hours:
            continue
        truth = hourly.loc[hours_idx[:n]].to_numpy(dtype=float)
        rng = np.random.default_rng([seed, 31, int(s.value // 10**9)])
        lead = np.arange(n, dtype=float)
        t0, t24 = temperature_sigma
        i0, i24 = irradiance_sigma
        sig_t = t0 + (t24 - t0) * lead / 24.0
        sig_i = i0 + (i24 - i0) * lead / 24.0
        temp_f = truth[:, 0] + sig_t * _ar1(rng, n, 0.9)
        factor = np.maximum(0.0, 1.0 + sig_i * _ar1(rng, n, 0.8))
        ghi = np.minimum(truth[:, 1] * factor, 1300.0)
        dni = np.minimum(truth[:, 2] * factor, 1100.0)
        dhi = np.minimum(truth[:, 3] * factor, 800.0)
        out.append({"issued": s.isoformat(), "source": f"testbed seed {seed}",
                    "times": [t.isoformat() for t in hours_idx[:n]],
                    "temperature": np.round(temp_f, 3).tolist(),
                    "ghi": np.round(ghi, 2).tolist(), "dni": np.round(dni, 2).tolist(),
                    "dhi": np.round(dhi, 2).tolist()})
    return out


def write_weather_forecasts(campaign: Path, *, seed: int = 0, out: Path | None = None,
                            **kwargs) -> Path:
    """Forecasts for a campaign folder (site.yaml, telemetry.csv) written as JSON
    (``weather_forecasts.json``: error model, seed and the bodies)."""
    campaign = Path(campaign)
    site = load_site(campaign / "site.yaml")
    frame = load_telemetry(campaign / "telemetry.csv", site).frame
    bodies = weather_forecasts(site, frame, seed=seed, **kwargs)
    path = Path(out) if out is not None else campaign / "weather_forecasts.json"
    model = dict(ERROR_MODEL)
    for key, name in (("temperature_sigma", "temperature_sigma_k"),
                      ("irradiance_sigma", "irradiance_sigma")):
        if key in kwargs:
            model[name] = [float(v) for v in kwargs[key]]
    path.write_text(json.dumps({"seed": seed, "error_model": model, "forecasts": bodies}))
    return path
