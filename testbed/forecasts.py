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
- irradiance error (``irradiance_error="cloud"``, the default since 2026-12-07), in the
  clear-sky index k = GHI / GHI_clear (pvlib's Ineichen clear sky at the hour): k_f = k +
  sigma(k, lead) xi(lead), xi a unit-variance AR(1) with correlation 0.8 per hour, the
  standard deviation set by the hour's sky: sigma_clear = 0.03 + 0.04 lead / 24 where
  k >= 0.9 (clear), sigma_I = 0.10 + 0.25 lead / 24 where k <= 0.4 (cloudy), linear in k
  between; k_f held within [0, max(1, k)] (a forecast is not clearer than a clear sky).
  DNI and DHI move with the forecast GHI as Erbs' split says they would (the split of the
  forecast GHI minus that of the true GHI, added to the true DNI and DHI), so a cloud
  forecast in error moves beam and diffuse the opposite ways. Why this form: published
  verifications of numerical weather forecasts find their bias below 50 W/m2 on measured
  clear hours and above 200 W/m2 on cloudy hours near noon (Mathiesen & Kleissl 2011,
  Solar Energy 85, 967-977), and the best day-ahead forecasts about 50 % better than
  persistence (Perez et al. 2013, Solar Energy 94, 305-326); docs/testbed.md "The weather
  forecasts' irradiance error" compares both forms with those figures;
- the earlier form (``irradiance_error="factor"``): multiplicative and the same factor for
  GHI, DNI and DHI, x_f = x max(0, 1 + sigma_I(lead) xi(lead)). It is as large on a clear
  hour as on a cloudy one, relative to the hour's irradiance (a clear noon a day ahead is
  off by a third), and no better than yesterday's irradiance;
- forecasts capped at 1300 / 1100 / 800 W/m2 (GHI / DNI / DHI);
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
import pvlib
from zonecast.estimator.site import Site, load_site
from zonecast.estimator.telemetry import load_telemetry

__all__ = ["CLOUD_MODEL", "ERROR_MODEL", "IRRADIANCE_ERRORS", "error_model",
           "weather_forecasts", "write_weather_forecasts"]

#: the irradiance error's forms (module docstring)
IRRADIANCE_ERRORS = ("factor", "cloud")
#: the ``cloud`` form's clear hours' standard deviation of the clear-sky index at lead 0
#: and 24 h [-], and the clear-sky index at or above which an hour counts as clear and at
#: or below which as cloudy (Mathiesen & Kleissl 2011's classes)
CLOUD_MODEL = {"clear_sigma": [0.03, 0.07], "clear_index": 0.9, "cloudy_index": 0.4}
#: the default error model (module docstring), recorded with every set of forecasts;
#: ``irradiance_sigma`` is the cloudy hours' in the ``cloud`` form, the factor's in the
#: ``factor`` form (the default until 2026-12-07)
ERROR_MODEL = {"temperature_sigma_k": [0.3, 2.0], "temperature_rho_per_h": 0.9,
               "irradiance_error": "cloud", "irradiance_sigma": [0.10, 0.35],
               "irradiance_rho_per_h": 0.8, "at_lead_h": [0, 24], **CLOUD_MODEL}


def _cloud_irradiance(site: Site, times: pd.DatetimeIndex, truth: np.ndarray,
                      sigma_cloudy: np.ndarray, sigma_clear: np.ndarray,
                      xi: np.ndarray) -> np.ndarray:
    """GHI, DNI, DHI forecasts [W/m2] (n x 3) of the ``cloud`` error form: truth (n x 3)
    moved by an error ``sigma(k) xi`` in the clear-sky index k (module docstring)."""
    loc = pvlib.location.Location(site.location.latitude, site.location.longitude,
                                  altitude=site.location.elevation)
    pos = loc.get_solarposition(times)
    clear = loc.get_clearsky(times, solar_position=pos)["ghi"].to_numpy()
    ghi, dni, dhi = truth[:, 0], truth[:, 1], truth[:, 2]
    day = clear > 1.0
    k = np.where(day, ghi / np.where(day, clear, 1.0), 0.0)
    lo, hi = CLOUD_MODEL["cloudy_index"], CLOUD_MODEL["clear_index"]
    cloudiness = np.clip((hi - k) / (hi - lo), 0.0, 1.0)
    sigma = sigma_clear + (sigma_cloudy - sigma_clear) * cloudiness
    k_f = np.clip(k + sigma * xi, 0.0, np.maximum(1.0, k))
    ghi_f = np.where(day, np.maximum(0.0, ghi + (k_f - k) * clear), ghi)  # exact at zero error
    zenith = pos["zenith"].to_numpy()
    split_f = pvlib.irradiance.erbs(ghi_f, zenith, times)
    split_t = pvlib.irradiance.erbs(ghi, zenith, times)
    moved = {c: np.nan_to_num(split_f[c].to_numpy() - split_t[c].to_numpy())
             for c in ("dni", "dhi")}
    dni_f = np.where(day, np.maximum(0.0, dni + moved["dni"]), dni)
    dhi_f = np.where(day, np.maximum(0.0, dhi + moved["dhi"]), dhi)
    return np.column_stack([ghi_f, dni_f, dhi_f])


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
                      temperature_sigma: tuple[float, float] = tuple(
                          ERROR_MODEL["temperature_sigma_k"]),
                      irradiance_sigma: tuple[float, float] = tuple(
                          ERROR_MODEL["irradiance_sigma"]),
                      irradiance_error: str = ERROR_MODEL["irradiance_error"],
                      clear_sigma: tuple[float, float] = tuple(
                          CLOUD_MODEL["clear_sigma"])) -> list[dict]:
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
    if irradiance_error not in IRRADIANCE_ERRORS:
        raise ValueError(f"irradiance_error must be one of {IRRADIANCE_ERRORS}, "
                         f"not {irradiance_error!r}")
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
        xi = _ar1(rng, n, 0.8)
        if irradiance_error == "factor":
            factor = np.maximum(0.0, 1.0 + sig_i * xi)
            rad = truth[:, 1:] * factor[:, None]
        else:
            c0, c24 = clear_sigma
            rad = _cloud_irradiance(site, hours_idx[:n], truth[:, 1:], sig_i,
                                    c0 + (c24 - c0) * lead / 24.0, xi)
        ghi = np.minimum(rad[:, 0], 1300.0)
        dni = np.minimum(rad[:, 1], 1100.0)
        dhi = np.minimum(rad[:, 2], 800.0)
        out.append({"issued": s.isoformat(), "source": f"testbed seed {seed}",
                    "times": [t.isoformat() for t in hours_idx[:n]],
                    "temperature": np.round(temp_f, 3).tolist(),
                    "ghi": np.round(ghi, 2).tolist(), "dni": np.round(dni, 2).tolist(),
                    "dhi": np.round(dhi, 2).tolist()})
    return out


def error_model(**kwargs) -> dict:
    """The error model that :func:`weather_forecasts` with these keyword arguments uses, as
    recorded in ``weather_forecasts.json`` (:data:`ERROR_MODEL` with the arguments')."""
    model = dict(ERROR_MODEL)
    for key, name in (("temperature_sigma", "temperature_sigma_k"),
                      ("irradiance_sigma", "irradiance_sigma"), ("clear_sigma", "clear_sigma")):
        if key in kwargs:
            model[name] = [float(v) for v in kwargs[key]]
    form = kwargs.get("irradiance_error", ERROR_MODEL["irradiance_error"])
    model["irradiance_error"] = form
    if form == "factor":
        for key in CLOUD_MODEL:
            model.pop(key)
    return model


def write_weather_forecasts(campaign: Path, *, seed: int = 0, out: Path | None = None,
                            **kwargs) -> Path:
    """Forecasts for a campaign folder (site.yaml, telemetry.csv) written as JSON
    (``weather_forecasts.json``: error model, seed and the bodies)."""
    campaign = Path(campaign)
    site = load_site(campaign / "site.yaml")
    frame = load_telemetry(campaign / "telemetry.csv", site).frame
    bodies = weather_forecasts(site, frame, seed=seed, **kwargs)
    path = Path(out) if out is not None else campaign / "weather_forecasts.json"
    model = error_model(**kwargs)
    path.write_text(json.dumps({"seed": seed, "error_model": model, "forecasts": bodies}))
    return path
