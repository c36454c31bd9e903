"""How much of the served forecast's error the weather forecasts' error makes (issue 15).

The served forecast (``zonecast reproduce``'s ``service`` row) runs on the testbed's
synthetic weather forecasts (:mod:`zonecast.testbed.forecasts`: the weather plus seeded
error growing with lead time). This benchmark issues the same served forecasts, at the same
validation midnights, with four error models built from the same random draws:

- ``as designed``: the testbed's error model (temperature 0.3 -> 2.0 K between lead 0 and
  24 h; irradiance by ``--irradiance-error``: ``cloud``, the default, in the clear-sky index,
  0.03 -> 0.07 on clear hours and 0.10 -> 0.35 on cloudy ones, or ``factor``, one factor
  0.10 -> 0.35 on every hour's irradiance);
- ``no error``: the weather itself (still hourly, interpolated by the service);
- ``temperature only`` and ``irradiance only``: one part of the error switched off;

and prints each one's RMS per zone, its ratio to the known-inputs forecast (issue 15's must:
<= 1.10) and the served 90 % interval coverage. Then, with the error-free weather forecasts,
which learned HVAC input costs most: the measured inputs with one group (airflows,
supply-air temperature, the boxes' discharge-air rise, all three) replaced by the service's
own input forecast at each issue (:meth:`OnlineEstimator.forecast_inputs`), and the
measured inputs with the boxes' reheat from the forecast's thermostat model
(``OnlineEstimator.forecast(thermostat_reheat=True)``).

    python benchmarks/bench_weather_error.py --campaign CAMPAIGN --report REPORT

``REPORT`` is a ``zonecast reproduce --campaign CAMPAIGN`` output folder (its model.json).
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # small matrices: threads only contend

import argparse
import json
import platform
import time
from pathlib import Path

import numpy as np
from zonecast.estimator.artifact import load_model_file
from zonecast.estimator.constants import HORIZON
from zonecast.estimator.pipeline import Pipeline
from zonecast.estimator.site import load_site
from zonecast.estimator.streaming import OnlineEstimator, has_discharge, model_rows, telemetry_frame
from zonecast.estimator.telemetry import load_telemetry
from zonecast.estimator.weather_forecast import parse_weather_forecast
from zonecast.testbed.forecasts import ERROR_MODEL, IRRADIANCE_ERRORS, weather_forecasts

from zonecast.jobs.reproduce import measured_inputs, service_check, validation_issues

DESIGNED_T = tuple(ERROR_MODEL["temperature_sigma_k"])
DESIGNED_I = tuple(ERROR_MODEL["irradiance_sigma"])
DESIGNED_C = tuple(ERROR_MODEL["clear_sigma"])
THERMOSTAT = "thermostat's reheat"
NONE = (0.0, 0.0)
#: (temperature, irradiance (the factor's or the cloudy hours'), clear hours') sigmas
CASES = {"as designed": (DESIGNED_T, DESIGNED_I, DESIGNED_C), "no error": (NONE, NONE, NONE),
         "temperature only": (DESIGNED_T, NONE, NONE),
         "irradiance only": (NONE, DESIGNED_I, DESIGNED_C)}


def hvac_attribution(model: Path, campaign: Path, data, weather) -> dict:
    """RMS per zone [K] of the forecasts at the validation midnights with the measured
    inputs (``known``) and with one group of HVAC inputs from the service's own forecast."""
    bundle = load_model_file(model)
    issues = {data.times[r].tz_convert("UTC"): (r, stop)
              for r, stop in validation_issues(data, 0)}
    nb, rise = data.u.shape[1], has_discharge(bundle)
    groups = {"airflows": list(range(nb)), "supply-air temperature": [nb + 1]}
    if rise:
        groups["discharge-air rise"] = list(range(nb + 7, 2 * nb + 7))
    groups["all three"] = sorted(c for cols in groups.values() for c in cols)
    frame = telemetry_frame(campaign / "telemetry.csv", bundle)
    rows = model_rows(bundle, frame[frame.notna().any(axis=1)])
    est = OnlineEstimator(bundle)
    wfs, j = sorted(weather, key=lambda w: w.issued), 0
    # the boxes' reheat from the forecast's thermostat model instead of the measured rise
    extra = [THERMOSTAT] if rise and bundle.site.thermostat is not None else []
    preds: dict[str, list] = {g: [] for g in ["known", *groups, *extra]}
    meas = []
    for k, t in enumerate(rows.times):
        if t > max(issues):
            break
        while j < len(wfs) and wfs[j].issued <= t:
            est.set_weather_forecast(wfs[j])
            j += 1
        est.advance(t, rows.u[k], rows.v[k], rows.y[k], rows.reheat[k])
        if t not in issues or not est.started:
            continue
        r, stop = issues[t]
        known = measured_inputs(data, r, r + HORIZON, rise)
        if len(known) < HORIZON or not np.isfinite(known).all():
            continue
        learned = est.forecast_inputs()
        y = np.full((HORIZON, len(data.zones)), np.nan)
        n = min(HORIZON, stop - r - 1)
        y[:n] = data.y[r + 1:r + 1 + n]
        meas.append(y)
        preds["known"].append(est.forecast(known).mean)
        for g, cols in groups.items():
            mix = known.copy()
            mix[:, cols] = learned[:, cols]
            preds[g].append(est.forecast(mix).mean)
        if extra:
            preds[extra[0]].append(est.forecast(known, thermostat_reheat=True).mean)
    out = {}
    for g, p in preds.items():
        rms = np.sqrt(np.nanmean((np.array(p) - np.array(meas)) ** 2, axis=(0, 1)))
        out[g] = {**dict(zip(data.zones, rms.tolist())), "mean": float(rms.mean())}
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--campaign", type=Path, required=True)
    ap.add_argument("--report", type=Path, required=True,
                    help="zonecast reproduce output folder (model.json)")
    ap.add_argument("--seed", type=int, default=0, help="seed of the forecast errors")
    ap.add_argument("--irradiance-error", choices=IRRADIANCE_ERRORS,
                    default=ERROR_MODEL["irradiance_error"],
                    help="the testbed's irradiance error form (docs/testbed.md)")
    ap.add_argument("--cases", default=",".join(CASES),
                    help=f"comma-separated weather error cases, of: {', '.join(CASES)}")
    ap.add_argument("--no-attribution", action="store_true",
                    help="leave out the learned HVAC inputs' table (the slowest part)")
    ap.add_argument("--json", type=Path, default=None,
                    help="also write the cases' RMS and coverage here")
    args = ap.parse_args()
    cases = [c.strip() for c in args.cases.split(",") if c.strip()]
    if not cases or any(c not in CASES for c in cases):
        raise SystemExit(f"--cases: use some of {', '.join(CASES)} (got {args.cases!r})")
    model = args.report / "model.json"
    if not model.is_file():
        raise SystemExit(f"{model} not found: run zonecast reproduce --campaign "
                         f"{args.campaign} --out {args.report} first")
    site = load_site(args.campaign / "site.yaml")
    frame = load_telemetry(args.campaign / "telemetry.csv", site).frame
    data = Pipeline.from_site(args.campaign / "site.yaml").data(args.campaign / "telemetry.csv")
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores; {args.campaign.name}, "
          f"forecast seed {args.seed}, irradiance error {args.irradiance_error!r}", flush=True)
    rows = {}
    known = None
    for name in cases:
        sig_t, sig_i, sig_c = CASES[name]
        t = time.perf_counter()
        bodies = weather_forecasts(site, frame, seed=args.seed, temperature_sigma=sig_t,
                                   irradiance_sigma=sig_i, clear_sigma=sig_c,
                                   irradiance_error=args.irradiance_error)
        out = service_check(model, args.campaign / "telemetry.csv", data, 0,
                            weather=[parse_weather_forecast(b) for b in bodies])
        rows[name] = (out["table3"]["service"], out["coverage_90"]["service"])
        known = out["table3"]["service_known_inputs"]
        print(f"{name:17s} served RMS {rows[name][0]['mean']:.3f} K, known inputs "
              f"{known['mean']:.3f} K ({time.perf_counter() - t:.0f} s)", flush=True)
    zones = [z for z in known if z != "mean"]
    print()
    print("| weather forecast error | " + " | ".join(zones)
          + " | mean | / known inputs | 90 % coverage (all, zones min-max) |")
    print("|---|" + "---|" * (len(zones) + 3))
    for name, (rms, cov) in rows.items():
        zc = [cov[z] for z in zones if z in cov]
        print(f"| {name} | " + " | ".join(f"{rms[z]:.3f}" for z in zones)
              + f" | **{rms['mean']:.3f}** | {rms['mean'] / known['mean']:.3f} | "
              f"{cov.get('all', float('nan')):.3f} ({min(zc):.3f}-{max(zc):.3f}) |")
    print("| known inputs (measured weather and HVAC) | "
          + " | ".join(f"{known[z]:.3f}" for z in zones) + f" | {known['mean']:.3f} | 1 | |")
    if args.json is not None:
        args.json.write_text(json.dumps({
            "campaign": args.campaign.name, "irradiance_error": args.irradiance_error,
            "seed": args.seed, "known_inputs": known,
            "cases": {n: {"rms": r, "coverage": c} for n, (r, c) in rows.items()}}, indent=1))
    if args.no_attribution:
        return
    t = time.perf_counter()
    perfect = [parse_weather_forecast(b) for b in weather_forecasts(
        site, frame, seed=args.seed, temperature_sigma=NONE, irradiance_sigma=NONE,
        clear_sigma=NONE, irradiance_error=args.irradiance_error)]
    attr = hvac_attribution(model, args.campaign, data, perfect)
    print(f"\nmeasured inputs with one learned HVAC group, error-free weather forecasts "
          f"({time.perf_counter() - t:.0f} s):\n")
    print("| inputs | " + " | ".join(zones) + " | mean |")
    print("|---|" + "---|" * (len(zones) + 1))
    for g, rms in attr.items():
        label = ("measured" if g == "known" else f"measured, {g}" if g == THERMOSTAT
                 else f"measured, learned {g}")
        print(f"| {label} | " + " | ".join(f"{rms[z]:.3f}" for z in zones)
              + f" | **{rms['mean']:.3f}** |")


if __name__ == "__main__":
    main()
