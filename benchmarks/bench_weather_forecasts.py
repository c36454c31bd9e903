"""The testbed's synthetic irradiance forecasts against published verification figures.

For each campaign folder (site.yaml, telemetry.csv) and each irradiance-error form of
:func:`zonecast.testbed.forecasts.weather_forecasts` (``factor``, ``cloud``), the GHI of
every 6-h issue against the weather itself, on daylight hours (clear-sky GHI > 50 W/m2,
pvlib's Ineichen) at leads 12-36 h:

- RMSE [W/m2], relative RMSE and relative MAE (over the mean true GHI), mean bias;
- skill against persistence: 1 - RMSE / RMSE of the same hour a day earlier;
- clear hours (clear-sky index > 0.8): RMSE and bias, the literature's "below 50 W/m2"
  (Mathiesen & Kleissl 2011);
- cloudy hours near noon (index < 0.4, clear-sky GHI > 600 W/m2): RMSE and bias, the
  literature's "above 200 W/m2";
- DNI RMSE, and the share of clear hours.

docs/testbed.md "The weather forecasts' irradiance error" holds the table and the figures
it is compared with. Campaigns with the same weather and weeks give the same rows.

    python benchmarks/bench_weather_forecasts.py runs/family-c/office6 runs/family-c/f0-03-tampa
"""

from __future__ import annotations

import argparse
import platform
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pvlib
from zonecast.estimator.site import load_site
from zonecast.estimator.telemetry import load_telemetry
from zonecast.testbed.forecasts import IRRADIANCE_ERRORS, weather_forecasts

NONE = (0.0, 0.0)
COLUMNS = ["RMSE", "rel. RMSE", "rel. MAE", "bias", "skill vs persistence", "clear RMSE",
           "clear bias", "cloudy-noon RMSE", "cloudy-noon bias", "DNI RMSE", "clear share"]


def forecast_table(site, frame, form: str, seed: int = 0) -> pd.DataFrame:
    """One row per forecast hour: lead [h], forecast and true GHI and DNI, clear-sky GHI and
    the true GHI a day earlier (NaN where the campaign has no such hour) [W/m2]."""
    fcs = weather_forecasts(site, frame, seed=seed, irradiance_error=form)
    truth = weather_forecasts(site, frame, seed=seed, temperature_sigma=NONE,
                              irradiance_sigma=NONE, clear_sigma=NONE, irradiance_error=form)
    loc = pvlib.location.Location(site.location.latitude, site.location.longitude,
                                  altitude=site.location.elevation)
    seen = pd.Series({pd.Timestamp(t): g for b in truth for t, g in zip(b["times"], b["ghi"])})
    seen = seen[~seen.index.duplicated()].sort_index()
    rows = []
    for f, t in zip(fcs, truth):
        times = pd.DatetimeIndex(f["times"])
        rows.append(pd.DataFrame({
            "lead": (times - pd.Timestamp(f["issued"])).total_seconds() / 3600.0,
            "f": f["ghi"], "t": t["ghi"], "dni_f": f["dni"], "dni_t": t["dni"],
            "clear": loc.get_clearsky(times)["ghi"].to_numpy(),
            "yesterday": seen.reindex(times - pd.Timedelta("24h")).to_numpy()}))
    return pd.concat(rows, ignore_index=True)


def statistics(d: pd.DataFrame, leads: tuple[float, float] = (12.0, 36.0)) -> dict:
    """The figures of the module docstring from :func:`forecast_table`'s rows."""
    d = d[(d["clear"] > 50.0) & (d["lead"] >= leads[0]) & (d["lead"] <= leads[1])]
    k = d["t"] / d["clear"]
    e = d["f"] - d["t"]
    p = d[np.isfinite(d["yesterday"])]
    clear = d[k > 0.8]
    cloudy = d[(k < 0.4) & (d["clear"] > 600.0)]

    def rmse(x):
        return float(np.sqrt(np.mean(np.square(x)))) if len(x) else float("nan")

    return {"RMSE": rmse(e), "rel. RMSE": rmse(e) / d["t"].mean(),
            "rel. MAE": float(e.abs().mean() / d["t"].mean()), "bias": float(e.mean()),
            "skill vs persistence": 1.0 - rmse(p["f"] - p["t"]) / rmse(p["yesterday"] - p["t"]),
            "clear RMSE": rmse(clear["f"] - clear["t"]),
            "clear bias": float((clear["f"] - clear["t"]).mean()),
            "cloudy-noon RMSE": rmse(cloudy["f"] - cloudy["t"]),
            "cloudy-noon bias": float((cloudy["f"] - cloudy["t"]).mean()),
            "DNI RMSE": rmse(d["dni_f"] - d["dni_t"]), "clear share": float((k > 0.8).mean())}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("campaigns", type=Path, nargs="+", help="campaign folders")
    ap.add_argument("--seed", type=int, default=0, help="seed of the forecast errors")
    args = ap.parse_args()
    print(f"machine: {platform.machine()}; seed {args.seed}; leads 12-36 h; GHI [W/m2]",
          flush=True)
    print("| campaign | form | " + " | ".join(COLUMNS) + " |")
    print("|---|---|" + "---|" * len(COLUMNS))
    for camp in args.campaigns:
        site = load_site(camp / "site.yaml")
        frame = load_telemetry(camp / "telemetry.csv", site).frame
        for form in IRRADIANCE_ERRORS:
            t = time.perf_counter()
            s = statistics(forecast_table(site, frame, form, args.seed))
            cells = [f"{s[c]:.3f}" if c in ("rel. RMSE", "rel. MAE", "skill vs persistence",
                                             "clear share") else f"{s[c]:.0f}" for c in COLUMNS]
            print(f"| {camp.name} | {form} | " + " | ".join(cells)
                  + f" |  <!-- {time.perf_counter() - t:.1f} s -->", flush=True)


if __name__ == "__main__":
    main()
