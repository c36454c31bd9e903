"""`zonecast reproduce`: the paper's tables and figures on a site's data (the main job).

Runs (or reuses) the virtual building's campaign, identifies the parameters (paper 4-A),
estimates the internal gains and forecasts (4-B, 5), and writes ``results.json`` (schema
below), figures (PNG) and ``report.md`` with Tables 1-3 beside the paper's numbers.
"""

from __future__ import annotations

import datetime as dt
import json
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from matplotlib.figure import Figure
from pydantic import BaseModel, ConfigDict, Field

from zonecast.estimator.artifact import model_options_dict
from zonecast.estimator.constants import HORIZON
from zonecast.estimator.dataset import ModelData
from zonecast.estimator.evaluate import horizon_rms, rms_by_zone
from zonecast.estimator.forecast import issue_rows, week_split
from zonecast.estimator.gains import REHEAT_LEAK_BOUNDS
from zonecast.estimator.identify import weekend_simulations
from zonecast.estimator.pipeline import (
    METERED_OCCUPIED_RATIO,
    OPERATING_FILMS_MODE,
    REHEAT_LEAK,
    WEEKEND_DAY_GAIN,
    WEEKEND_DAY_HOURS,
    Pipeline,
    check_constant_gains,
    check_reheat_leak,
    identify_operating_films,
    weekend_daytime_shape,
    weekend_occupancy_warning,
)
from zonecast.estimator.rc.network import ModelOptions
from zonecast.estimator.streaming import has_discharge
from zonecast.estimator.study import forecast_study
from zonecast.estimator.weather_forecast import parse_weather_forecast

RESULTS_SCHEMA_VERSION = 1

#: the paper's numbers (Hu et al., Tables 2 and 3), for the report
PAPER = {
    "table2": {"training": {"NW": 0.46, "W": 0.41, "S": 0.24, "E": 0.34, "NE": 0.27, "C": 0.28,
                            "mean": 0.333},
               "validation": {"NW": 0.62, "W": 0.57, "S": 0.31, "E": 0.28, "NE": 0.39, "C": 0.31,
                              "mean": 0.413}},
    "table3": {"fixed": {"NW": 0.84, "W": 0.42, "S": 0.48, "E": 0.43, "NE": 0.36, "C": 0.38,
                         "mean": 0.485},
               "online_paper": {"NW": 0.50, "W": 0.31, "S": 0.15, "E": 0.41, "NE": 0.32,
                                "C": 0.16, "mean": 0.308}},
}

ZoneRms = dict[str, float]


class Parameter(BaseModel):
    value: float
    unit: str
    stderr: float | None = None
    bounds: tuple[float, float] | None = None
    at_bound: bool = False


class Results(BaseModel):
    """Schema of ``results.json`` (validated when written and in the tests)."""

    model_config = ConfigDict(extra="allow")
    schema_version: int = RESULTS_SCHEMA_VERSION
    seed: int
    parameters: dict[str, Parameter]
    table2: dict[str, ZoneRms | None] = Field(description="training, validation: zone -> RMS [K]")
    table3: dict[str, ZoneRms] = Field(description="fixed, online_paper, dayahead: zone -> RMS [K]")
    horizon_rms: dict[str, dict[str, list[float]]] = Field(
        description="method -> zone -> RMS [K] per horizon step (15 min ... 24 h)")
    table2_window_solar_air: dict[str, ZoneRms | None] | None = Field(
        None, description="Table 2 with window solar on the room air (the paper's placement), "
                          "one start: a sensitivity")
    model_options: dict[str, str | float] | None = Field(
        None, description="ModelOptions of the model")
    identification: dict[str, Any] | None = Field(
        None, description="identification details: correlations, starts, at_bounds, Jacobian "
                          "rank and condition")
    gains_truth: dict[str, Any] = Field(description="zone -> correlation with the true gains")
    coverage_90: Any = Field(description="empirical coverage of the 90 % forecast intervals")
    split: dict[str, Any] = Field(description="identification weekends and gains/forecast weeks")
    service_weather_error: str | None = Field(
        None, description="the testbed's weather-forecast irradiance error form of the "
                          "service check (WEATHER_ERRORS), None without the service check")
    timings_s: dict[str, float] = Field(default_factory=dict)


def _table(rows: dict[str, ZoneRms | None], zones: list[str], paper: dict | None = None) -> list[str]:
    head = "| | " + " | ".join(zones) + " | mean |"
    out = [head, "|---" * (len(zones) + 2) + "|"]
    for name, r in rows.items():
        if r is None:
            continue
        out.append(f"| {name} | " + " | ".join(f"{r.get(z, float('nan')):.3f}" for z in zones)
                   + f" | **{r['mean']:.3f}** |")
        if paper and name in paper:
            p = paper[name]
            out.append(f"| paper {name} | " + " | ".join(f"{p.get(z, float('nan')):.2f}"
                                                       for z in zones) + f" | {p['mean']:.3f} |")
    return out


def write_report(results: Results, out: Path, figures: list[str], zones: list[str]) -> Path:
    """``report.md`` with Tables 1-3 beside the paper's figures."""
    lines = ["# zonecast reproduce: Hu et al., tables and figures on the virtual building", "",
             f"Seed {results.seed}. Split: {json.dumps(results.split)}.", "",
             "## Table 1: identified parameters", "",
             "| parameter | value | std. error | unit | bounds | |", "|---|---|---|---|---|---|"]
    for n, p in results.parameters.items():
        se = "" if p.stderr is None else f"{p.stderr:.3g}"
        bounds = "" if p.bounds is None else f"[{p.bounds[0]:.4g}, {p.bounds[1]:.4g}]"
        flag = "**at a bound**" if p.at_bound else ""
        lines.append(f"| {n} | {p.value:.4g} | {se} | {p.unit} | {bounds} | {flag} |")
    pinned = [n for n, p in results.parameters.items() if p.at_bound]
    ident = results.identification or {}
    lines += ["", "Parameters at a bound (the data do not determine them; the bound does): "
              + (", ".join(pinned) if pinned else "none") + "."]
    if ident.get("jacobian_rank") is not None:
        lines.append(f"Identifiability: Jacobian rank {ident['jacobian_rank']} of "
                     f"{len(results.parameters)}, condition number "
                     f"{ident['jacobian_condition']:.3g}; strongly correlated pairs (|r| >= 0.9): "
                     + ("; ".join(f"{a}/{b} {r:+.2f}" for a, b, r in ident["strongly_correlated"])
                        or "none") + ".")
    operating = ident.get("operating_films")
    test = ident.get("operating_films_test")
    why = ("" if not test else
           f"the zones' mean reheat leak at the identified films k {test['k_mean']:+.3f} ± "
           f"{test['stderr']:.3f}, ")
    if operating:
        lines.append("Inside films in regular operation (internal gains, Table 3, the model "
                     "file): the identified ones × "
                     + ", ".join(f"{k} {v:.3f}" for k, v in operating.items())
                     + f" (`--operating-films`: {why}the building's inside convection is "
                     "natural, and on the testbed family's VAV floors the experiments hold the "
                     "faces further from the air than operation does; docs/identification.md "
                     "\"Operating films\"). Table 1 and Table 2 are the identified films.")
    elif test:
        lines.append("Inside films in regular operation: the identified ones "
                     f"(`--operating-films auto`: {why}below {test['min_t']:g} standard "
                     "errors, so operation does not ask for weaker films; "
                     "docs/identification.md \"Operating films\").")
    source = ident.get("x0_gains_source")
    if source == "meters":
        lines.append("x(0) filter: the working day before each weekend with each zone's "
                     "metered lights and plug loads above their base as known gains "
                     "(`--x0-meters`, on where the site has meters; docs/identification.md "
                     "\"The x(0) filter told the meters\").")
    elif source == "profile":
        lines.append("x(0) filter: the days before each weekend with the weekly internal-gains "
                     "profile as known gains (`--x0-profile-days`).")
    leak = ident.get("reheat_leak")
    if leak:
        lines.append("Reheat heat in regular operation (internal gains, Table 3, the model "
                     "file): on the room air the measured heat × 1 + k (with `from_faces`, "
                     "the default, k × the heat taken from the room's faces), k per zone "
                     + ", ".join(f"{z} {v['k']:+.3f}"
                                 + (f" (**at its bound**; fitted {v['fitted']:+.3f})"
                                    if v["k"] != v["fitted"] and v["k"] != 0.0 else "")
                                 for z, v in leak.items())
                     + " (`--reheat-leak added|from_faces`: the share of the reheat that the "
                     "training weeks' gains estimate carried, fitted with the weekly profile "
                     "within time-of-week bins; 0 where not significant, bounds "
                     f"{REHEAT_LEAK_BOUNDS[0]} and {REHEAT_LEAK_BOUNDS[1]}; "
                     "docs/identification.md \"The reheat leak fitted from operation\"). "
                     "Table 2 is the identified model's.")
    spans = (results.identification or {}).get("spans") or []
    mode = (results.identification or {}).get("weekend_gains")
    lines += ["", "## Table 2: identification RMS [°C] (weekend data, "
              + ("f_IG = 0)" if mode in (None, False, "none") else "weekend gains in the fit)"),
              ""]
    if spans:
        lines += ["Hours fitted (training) and scored (validation), local time, window "
                  f"`{results.identification.get('window', 'weekend')}`: "
                  + "; ".join(f"{s['role']} {s['start'][:16]} to {s['end'][:16]}"
                              for s in spans) + ".", ""]
    ident_d = results.identification or {}
    if ident_d.get("weekend_gains_asked") == "auto":
        ratio = ident_d.get("weekend_metered_ratio")
        lines += [("Weekend gains chosen from the site's meters (`--weekend-gains auto`, the "
                   "default): "
                   + ("no lights and plug-load meters, so the weekend daytime rise"
                      if ratio is None else
                      f"their weekend daytime rise is {ratio:.2f} of the working days' "
                      f"(threshold {METERED_OCCUPIED_RATIO}), so "
                      + ("the weekends are occupied and the metered rise is known gains"
                         if mode == "metered" else "the weekends are not occupied and the "
                         "weekend daytime rise"))
                   + " (docs/identification.md \"Metered gains where the weekends are "
                   "occupied\")."), ""]
    if mode in (True, "known"):
        lines += [("Fitted with the weekly internal-gains profile of the training weeks without "
                   "experiments as known f_IG (`--weekend-gains known`), so Table 2 is the model "
                   "with that profile, not the paper's f_IG = 0."), ""]
    elif mode == "daytime":
        scale = (results.identification or {}).get("gain_scale") or {}
        lines += [("Fitted with a weekend daytime rise of the internal gains, s_z × "
                   f"{WEEKEND_DAY_GAIN} W/m² between {WEEKEND_DAY_HOURS[0]:02d} and "
                   f"{WEEKEND_DAY_HOURS[1]:02d} h local on Saturdays and Sundays, its per-zone "
                   "scale fitted with the parameters (`--weekend-gains daytime`, the default "
                   "without meters or occupied weekends; `none` gives the paper's f_IG = 0), "
                   "so Table 2 and Fig. 1 are the model with those gains. Scales: "
                   + _scales(scale) + "."), ""]
        occupied = weekend_occupancy_warning(
            scale, day_scale=(results.identification or {}).get("gain_day_scale"),
            metered=bool((results.identification or {}).get("site_meters")),
            metered_ratio=(results.identification or {}).get("weekend_metered_ratio"))
        if occupied:
            lines += [f"**Warning:** {occupied}.", ""]
    elif mode == "metered":
        scale = (results.identification or {}).get("gain_scale") or {}
        lines += [("Fitted with each zone's metered lights and plug loads above its weekend "
                   "night base, per m² of floor, as known weekend gains, and the weekend "
                   f"daytime rise s_z × {WEEKEND_DAY_GAIN} W/m² between "
                   f"{WEEKEND_DAY_HOURS[0]:02d} and {WEEKEND_DAY_HOURS[1]:02d} h local with its "
                   "per-zone scale fitted with the parameters (`--weekend-gains metered`), so "
                   "Table 2 and Fig. 1 are the model with those gains. Scales: "
                   + _scales(scale) + "."), ""]
    elif mode == "scaled":
        scale = (results.identification or {}).get("gain_scale") or {}
        lines += [("Fitted with the weekly internal-gains profile of the training weeks without "
                   "experiments as a per-zone shape whose scale was fitted with the parameters "
                   "(`--weekend-gains scaled`), so Table 2 is the model with those gains, not the "
                   "paper's f_IG = 0. Scales: "
                   + _scales(scale) + "."), ""]
    offsets = (results.identification or {}).get("x0_offsets")
    if offsets:
        prior = next(iter(offsets.values())).get("prior_sd")
        lines += [("Every weekend, the validation one included, starts at the x(0) filter's "
                   "state plus one fitted offset per zone of the slow states (walls' layers, "
                   "slabs, furniture; `--x0-offset-sd`"
                   + (f", prior 0 ± {prior:g} K" if prior else "") + "): "
                   + ", ".join(f"{z} {v['value']:+.2f} ± {v['se']:.2f} K"
                               for z, v in offsets.items()) + "."), ""]
    lines += _table(results.table2, zones, PAPER["table2"])
    if results.table2_window_solar_air:
        lines += ["", (f"Model options: {json.dumps(results.model_options)}. Sensitivity, the same "
                  "identification (one start) with window solar on the room air as the paper "
                  "places it (docs/identification.md):"), ""]
        lines += _table({f"{k}, window solar on air": v
                         for k, v in results.table2_window_solar_air.items()}, zones)
    lines += ["", "## Table 3: 24-hour prediction RMS [°C]", ""]
    lines += _table(results.table3, zones, PAPER["table3"])
    if "service" not in results.table3:
        lines += ["", ("The service check (the served forecast, its input forecasts and "
                       "calibrated intervals) was left out (`zonecast reproduce "
                       "--no-service`).")]
    if getattr(results, "service_weather_error", None):
        lines += ["", (f"The served forecast's weather forecasts: the testbed's "
                       f"`{results.service_weather_error}` irradiance error "
                       "(docs/testbed.md).")]
    attribution = getattr(results, "service_input_attribution", None)
    if attribution:
        lines += ["", ("Served forecast, which input's persistence costs most (known inputs "
                       "with one group persisted):"), ""]
        lines += _table(attribution, zones)
    lines += ["", f"Coverage of the 90 % intervals: {json.dumps(results.coverage_90)}", "",
              "## Internal gains against the truth (r per zone)", "",
              "```", json.dumps(results.gains_truth, indent=1)[:4000], "```", ""]
    lines += [f"![{f}]({f})" for f in figures]
    lines += ["", f"Timings [s]: {json.dumps(results.timings_s)}"]
    path = out / "report.md"
    path.write_text("\n".join(lines) + "\n")
    return path


def plot_gains(fig2: dict, zones: list[str], path: Path) -> None:
    """Fig. 2: temperature rise per step due to internal gains, C B_IG (c_IG + f_IG,w), per
    zone on the local time-of-week axis: each training week in grey, their mean in red."""
    fig = Figure(figsize=(10, 1.5 * len(zones)))
    axes = fig.subplots(len(zones), 1, sharex=True)
    for ax, z in zip(np.atleast_1d(axes), zones):
        days = np.arange(len(fig2[z]["mean"])) / 96.0
        for w in fig2[z]["weeks"]:
            ax.plot(days, np.asarray(w, dtype=float), color="0.75", lw=0.6)
        ax.plot(days, np.asarray(fig2[z]["mean"], dtype=float), color="red", lw=1.2)
        ax.set_ylabel(f"{z} [K]")
    np.atleast_1d(axes)[-1].set_xlabel("day of week (0 = Monday 00:00 local)")
    fig.suptitle("Temperature rise per 15-min step due to internal gains: weeks grey, mean red")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def plot_horizon(horizon: dict[str, dict[str, list[float]]], zones: list[str], path: Path) -> None:
    """Fig. 3: RMS versus prediction horizon, per zone, one panel per method."""
    methods = list(horizon)
    fig = Figure(figsize=(4.5 * len(methods), 3.6))
    axes = fig.subplots(1, len(methods), sharey=True)
    for ax, m in zip(np.atleast_1d(axes), methods):
        for z in zones + ["mean"]:
            vals = horizon[m].get(z)
            if vals is None:
                continue
            h = (np.arange(len(vals)) + 1) * 0.25
            ax.plot(h, vals, label=z, lw=2.0 if z == "mean" else 1.0,
                    color="k" if z == "mean" else None)
        ax.set_title(m)
        ax.set_xlabel("horizon [h]")
    np.atleast_1d(axes)[0].set_ylabel("RMS [°C]")
    np.atleast_1d(axes)[0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def _scales(scale: dict) -> str:
    """The fitted gains scales of a report line: "N 0.12 ± 0.03, ..."."""
    return ", ".join(f"{z} {v['value']:.2f} ± {v['se']:.2f}" for z, v in scale.items())


def _daytime_gains(mode, ident, data, pipe=None) -> np.ndarray | None:
    """The weekend gains [W/m2] a ``daytime`` or ``metered`` fit knew: the fitted rise
    s_z x shape (with each training day's own deviation) plus, for ``metered`` (with the
    pipeline ``pipe``), the metered gains; else None."""
    scale = ident.gain_scale if mode in ("daytime", "metered") else None
    if not scale:
        return None
    shape = weekend_daytime_shape(data)
    gains = shape * np.array([scale[z]["value"] for z in data.zones])
    # each training day's own deviation (identify(day_scale_sd=)), as Table 2 scored it
    dates = np.asarray(data.local_times().date)
    for key, d in (ident.gain_day_scale or {}).items():
        zone, day = key.rsplit(",", 1)
        j = data.zones.index(zone)
        on = dates == dt.date.fromisoformat(day)
        gains[on, j] += shape[on, j] * d["value"]
    known = pipe.weekend_known_gains(data, mode) if pipe is not None else None
    return gains if known is None else gains + known


def plot_weekends(sims: list[dict], roles: dict[str, str], zones: list[str], path: Path,
                  gains: str = "f_IG = 0") -> None:
    """Fig. 1: the identification's simulations (``gains``: f_IG = 0, or the fitted weekend
    daytime rise) against the measured zone temperatures on each excitation weekend, one
    row per zone, one column per weekend."""
    fig = Figure(figsize=(4.2 * len(sims), 1.5 * len(zones)))
    axes = fig.subplots(len(zones), len(sims), sharex='col', squeeze=False)
    for c, w in enumerate(sims):
        hours = np.arange(len(w["measured"])) * 0.25
        for r, z in enumerate(zones):
            ax = axes[r, c]
            meas, sim = w["measured"][:, r], w["simulated"][:, r]
            rms = float(np.sqrt(np.nanmean((sim - meas) ** 2)))
            ax.plot(hours, meas, ".", ms=1.5, color="k")
            ax.plot(hours, sim, color="tab:red", lw=0.9)
            ax.text(0.01, 0.85, f"RMS {rms:.2f} °C", transform=ax.transAxes, fontsize=7,
                    bbox={"facecolor": "white", "alpha": 0.7, "edgecolor": "none", "pad": 1})
            if c == 0:
                ax.set_ylabel(f"{z} [°C]")
        axes[0, c].set_title(f"{roles.get(w['saturday'], '')} weekend {w['saturday']}",
                             fontsize=9)
        axes[-1, c].set_xlabel("hours from Saturday 00:00 local")
    fig.suptitle(f"Fig. 1: identification weekends, model with {gains} (red) and measured (dots)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def plot_week(week: dict, zones: list[str], methods: list[str], title: str, path: Path) -> None:
    """Figs. 4 and 5: one validation week, measured zone temperatures (black) and the
    predictions of ``methods`` (24-h forecasts laid end to end per issue day, or the
    paper's online one-step predictions), one panel per zone."""

    t = pd.to_datetime(week["times"], utc=True)
    colors = {"fixed": "tab:blue", "dayahead": "tab:orange", "online_paper": "tab:green",
              "service": "tab:purple"}
    fig = Figure(figsize=(11, 1.7 * len(zones)))
    axes = fig.subplots(len(zones), 1, sharex=True)
    for ax, z in zip(np.atleast_1d(axes), zones):
        meas = np.asarray(week["measured"][z], dtype=float)
        ax.plot(t, meas, color="k", lw=1.0, label="measured")
        for m in methods:
            pred = np.asarray(week[m][z], dtype=float)
            ok = np.isfinite(pred) & np.isfinite(meas)
            rms = float(np.sqrt(np.mean((pred[ok] - meas[ok]) ** 2))) if ok.any() else np.nan
            ax.plot(t, pred, color=colors.get(m), lw=0.9, label=f"{m} (RMS {rms:.2f} °C)")
        ax.set_ylabel(f"{z} [°C]")
        ax.legend(fontsize=6, loc="upper right", ncol=len(methods) + 1)
    np.atleast_1d(axes)[-1].set_xlabel("time (UTC)")
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def _interval_coverage(lower: np.ndarray, upper: np.ndarray, meas: np.ndarray,
                       zones: list[str]) -> dict[str, float]:
    """Fraction of measurements inside [lower, upper], per zone and over all (``all``)."""
    ok = np.isfinite(meas) & np.isfinite(lower) & np.isfinite(upper)
    inside = (meas >= lower) & (meas <= upper)
    out = {z: float(inside[..., j][ok[..., j]].mean()) for j, z in enumerate(zones)}
    out["all"] = float(inside[ok].mean())
    return out


#: the testbed's irradiance-error forms (``zonecast.testbed.forecasts.IRRADIANCE_ERRORS``;
#: the first the default)
WEATHER_ERRORS = ("cloud", "factor")


def _weather_forecasts(campaign: Path, seed: int, weather_error: str = WEATHER_ERRORS[0],
                       progress=lambda s: None) -> list:
    """The campaign's weather forecasts, validated like those the service receives.

    ``weather_forecasts.json`` (``weather_forecasts-factor.json`` for the earlier
    ``factor`` error form) is used as it is when it holds forecasts from elsewhere (no
    ``error_model`` recorded); written by the testbed's error model (the weather file plus
    seeded error growing with lead time, docs/testbed.md) when absent, or again when the
    testbed wrote it with another seed or error model than asked for."""
    from zonecast.testbed.forecasts import error_model, write_weather_forecasts  # testbed extra

    name = "weather_forecasts.json" if weather_error == WEATHER_ERRORS[0] else \
        f"weather_forecasts-{weather_error}.json"
    path = campaign / name
    want = error_model(irradiance_error=weather_error)
    doc = json.loads(path.read_text()) if path.is_file() else None
    if doc is not None and "error_model" in doc and (
            doc.get("error_model") != want or doc.get("seed") != seed):
        progress(f"{name} was written with another seed or error model: writing it again")
        doc = None
    if doc is None:
        write_weather_forecasts(campaign, seed=seed, out=path, irradiance_error=weather_error)
        doc = json.loads(path.read_text())
    return [parse_weather_forecast(b) for b in doc["forecasts"]]


def validation_issues(data: ModelData, seed: int) -> list[tuple[int, int]]:
    """(issue row, last row of its week) of the day-ahead forecasts at the validation
    midnights of the forecast study's split (Table 3's issues)."""
    split = week_split(data, seed)
    return [(r, split["weeks"][i]["rows"][1]) for i in split["validation"]
            for r in issue_rows(data, split["weeks"][i]["rows"])]


def measured_inputs(data: ModelData, a: int, b: int, discharge: bool) -> np.ndarray:
    """Rows [a, b) of the served forecast's inputs as measured: u, v and, for a site with
    discharge-air points, each box's discharge-air rise."""
    parts = [data.u[a:b], data.v[a:b]] + ([data.reheat[a:b]] if discharge else [])
    return np.hstack(parts)


def service_check(model_file: Path, telemetry: Path, data: ModelData, seed: int,
                  weather: list | None = None) -> dict:
    """The service's day-ahead forecast (:class:`~zonecast.estimator.streaming.OnlineEstimator`:
    steady-state filter, online f_IG, input forecasts, calibrated intervals) issued at the
    same validation midnights as Table 3, computed offline from the telemetry file exactly
    as ``zonecast forecast`` does. Rows:

    - ``service``: the served forecast with the weather forecasts ``weather``
      (:class:`~zonecast.estimator.weather_forecast.WeatherForecast`; the testbed's, with
      error growing with lead time) and the learned HVAC inputs;
    - ``service_no_weather_forecast``: the same without weather forecasts (the diurnal
      fallback);
    - ``service_persistence``: the inputs measured 24 h earlier (the service before
      input forecasts);
    - ``service_known_inputs``: the measured u and v over the horizon (comparable with
      Table 3's rows);
    - ``attribution``: the known inputs with one group (airflows, outdoor temperature,
      supply-air temperature, facade solar) replaced by persistence: which input's
      persistence costs most.

    RMS per zone, per horizon, and coverage of the served 90 % intervals (``lower``,
    ``upper``: calibrated on the building's own recent errors) per zone and overall."""
    issues = validation_issues(data, seed)
    t0 = time.perf_counter()
    times = [data.times[r] for r, _ in issues]
    nb = data.u.shape[1]
    served = Pipeline.from_model_file(model_file)
    # with discharge-air points the inputs end with each box's discharge-air rise
    rh = has_discharge(served.bundle)

    def inputs_at(a: int, b: int) -> np.ndarray:
        return measured_inputs(data, a, b, rh)

    measured, persisted = {}, {}
    for r, _ in issues:
        ins = inputs_at(r, r + HORIZON)
        if len(ins) == HORIZON and np.isfinite(ins).all() and r >= HORIZON:
            measured[data.times[r]] = ins
            persisted[data.times[r]] = np.vstack([ins[:1], inputs_at(r + 1 - HORIZON, r)])
    # the forecasts without weather forecasts differ only in the inputs they are issued
    # with: one replay gives them all (the estimator's state does not depend on them)
    variants: dict = {"service_no_weather_forecast": None,
                      "service_persistence": "persistence",
                      "service_known_inputs": measured}
    groups = {"airflows": list(range(nb)), "outdoor_temperature": [nb],
              "supply_temperature": [nb + 1], "solar": list(range(nb + 2, nb + 6))}
    for g, cols in groups.items():
        mixed = {}
        for t, ins in measured.items():
            a = ins.copy()
            a[:, cols] = persisted[t][:, cols]
            mixed[t] = a
        variants[f"known_but_persisted_{g}"] = mixed
    runs = {"service": served.forecast(telemetry, times, weather=weather or []),
            **served.forecast_variants(telemetry, times, variants)}
    nz = len(data.zones)
    out: dict = {"table3": {}, "horizon_rms": {}, "coverage_90": {}, "attribution": {}}
    for name, fcs in runs.items():
        pred, lo, hi, meas = (np.full((len(issues), HORIZON, nz), np.nan) for _ in range(4))
        for k, (r, stop) in enumerate(issues):
            needs_measured = name == "service_known_inputs" or name.startswith("known_but")
            if needs_measured and data.times[r] not in measured:
                continue
            fc = fcs[data.times[r]]
            n = min(HORIZON, stop - r - 1)
            pred[k], lo[k], hi[k] = fc.mean, fc.lower, fc.upper
            meas[k, :n] = data.y[r + 1:r + 1 + n]
        rms = rms_by_zone(pred.reshape(-1, nz), meas.reshape(-1, nz), data.zones)
        if name.startswith("known_but"):
            out["attribution"][name] = rms
            continue
        out["table3"][name] = rms
        out["horizon_rms"][name] = horizon_rms(pred, meas, data.zones)
        out["coverage_90"][name] = _interval_coverage(lo, hi, meas, data.zones)
    out["n_forecasts"] = len(issues)
    out["seconds"] = time.perf_counter() - t0
    return out


def run(out: Path, campaign: Path | None = None, seed: int = 0, starts: int = 1,
        progress=lambda s: None, *, priors: bool = True, sigma_e: float = 0.3,
        window: str = "weekend", sensitivity: bool = True,
        infiltration: str = ModelOptions.infiltration, weekend_gains: bool | str = "auto",
        ground: str = ModelOptions.ground, shading: str = ModelOptions.shading, return_air: str = ModelOptions.return_air,
        roof_solar: str = ModelOptions.roof_solar, sky: str = ModelOptions.sky,
        interior_radiation: str = ModelOptions.interior_radiation, films: str | None = None,
        internal_gains: str = ModelOptions.internal_gains, service: bool = True,
        x0_profile_days: int | None = None, x0_offset_sd: float | None = None,
        window_angle: str = ModelOptions.window_angle, day_scale_sd: float | None = None,
        roof_exterior: str = ModelOptions.roof_exterior, envelope_radiation: str = ModelOptions.envelope_radiation,
        solar_enclosure: str = ModelOptions.solar_enclosure, adiabatic: str = ModelOptions.adiabatic,
        layers: str = ModelOptions.layers, internal_mass: str = ModelOptions.internal_mass,
        inside_convection: str = ModelOptions.inside_convection,
        roof_inside: str = ModelOptions.roof_inside,
        x0_meters: bool | str = "auto", constant_gains: str = "fitted",
        positive_priors: str = "log", operating_films: str = OPERATING_FILMS_MODE,
        reheat_leak: str = REHEAT_LEAK, weather_error: str = WEATHER_ERRORS[0]) -> Results:
    """The main job; see the module docstring. ``priors``, ``sigma_e``, ``window``: as
    :meth:`Pipeline.identify <zonecast.estimator.pipeline.Pipeline.identify>`;
    ``sensitivity``: also identify the paper's window-solar placement (one start);
    ``service``: also the service check (:func:`service_check`, Table 3's ``service*``
    rows and the calibrated coverage; most of the job's time on buildings whose boxes
    reheat); off, the report says it was left out; ``x0_profile_days``,
    ``x0_offset_sd``, ``day_scale_sd``: as :meth:`Pipeline.identify`;
    ``infiltration``, ``ground``, ``shading``, ``return_air``, ``roof_solar``, ``sky``,
    ``interior_radiation``, ``internal_gains``, ``window_angle``, ``roof_exterior``,
    ``envelope_radiation``, ``solar_enclosure``, ``adiabatic``, ``layers``, ``internal_mass``, ``inside_convection``,
    ``roof_inside``: :class:`~zonecast.estimator.rc.network.ModelOptions`;
    ``x0_meters``, ``constant_gains``: as :meth:`Pipeline.identify`;
    ``reheat_leak``: as ``zonecast identify`` (:meth:`Pipeline.fit_reheat_leak` on the
    training weeks of the gains split);
    ``films``, ``positive_priors``: as :meth:`Pipeline.identify`; ``operating_films``:
    one of :data:`~zonecast.estimator.pipeline.OPERATING_FILMS_OPTIONS` (``"auto"``, the
    default: :meth:`Pipeline.fit_operating_films` on the training weeks of the gains split)
    (the forecasts and gains use the pipeline's operating parameters, Table 2 and Fig. 1
    the identified ones);
    ``weekend_gains``: as :meth:`Pipeline.identify`, the profile from the training weeks of
    the forecast study's split (never its validation weeks); ``weather_error``: the form of
    the testbed's weather-forecast irradiance error the service check uses, one of
    :data:`WEATHER_ERRORS` (``zonecast.testbed.forecasts``)."""
    check_constant_gains(constant_gains)  # before the campaign and the weeks' split
    if weather_error not in WEATHER_ERRORS:
        raise ValueError(f"weather_error must be one of {', '.join(WEATHER_ERRORS)}, "
                         f"not {weather_error!r}")
    out.mkdir(parents=True, exist_ok=True)
    timings = {}
    t0 = time.perf_counter()
    if campaign is None or not (campaign / "telemetry.csv").is_file():
        from zonecast.testbed.run import run_campaign  # the testbed extra (EnergyPlus)
        campaign = campaign or out / "campaign"
        progress("virtual building campaign (EnergyPlus)")
        run_campaign(campaign, seed=seed, progress=lambda s: progress(f"campaign: {s}"))
    timings["campaign"] = time.perf_counter() - t0
    pipe = Pipeline.from_site(campaign / "site.yaml",
                              options=ModelOptions(infiltration=infiltration, ground=ground,
                                                   shading=shading, return_air=return_air,
                                                   roof_solar=roof_solar, sky=sky,
                                                   interior_radiation=interior_radiation,
                                                   internal_gains=internal_gains,
                                                   window_angle=window_angle,
                                                   roof_exterior=roof_exterior,
                                                   envelope_radiation=envelope_radiation,
                                                   solar_enclosure=solar_enclosure,
                                                   adiabatic=adiabatic, layers=layers,
                                                   internal_mass=internal_mass,
                                                   inside_convection=inside_convection,
                                                   roof_inside=roof_inside))
    site = pipe.site
    data = pipe.data(campaign / "telemetry.csv")
    t = time.perf_counter()
    progress("identification")
    ident = pipe.identify(data, n_starts=starts, seed=seed, priors=priors, sigma_e=sigma_e,
                          window=window, progress=lambda s: progress(f"identification: {s}"),
                          weekend_gains=weekend_gains, films=films,
                          gains_weeks=(week_split(data, seed)["train"]
                                       if weekend_gains not in (False, None, "none")
                                       or x0_profile_days else None),
                          x0_profile_days=x0_profile_days, x0_offset_sd=x0_offset_sd,
                          day_scale_sd=day_scale_sd, positive_priors=positive_priors,
                          operating_films=identify_operating_films(operating_films),
                          x0_meters=x0_meters, constant_gains=constant_gains)
    timings["identification"] = time.perf_counter() - t
    # sensitivity: the paper's placement of window solar (room air), one start
    progress("identification with window solar on the room air (paper's placement)")
    ident_air = pipe.with_options(replace(pipe.options, window_solar="air")).identify(
        data, n_starts=1, seed=seed, priors=priors, sigma_e=sigma_e,
        window=window, positive_priors=positive_priors) if sensitivity else None
    if operating_films == "auto":
        pipe.fit_operating_films(data, weeks=week_split(data, seed)["train"],
                                 progress=progress)
    leak = None
    if check_reheat_leak(reheat_leak) != "none":
        leak = pipe.fit_reheat_leak(data, weeks=week_split(data, seed)["train"],
                                    progress=progress, from_faces=reheat_leak == "from_faces")
    fitted = pipe.model()  # the films of regular operation (Pipeline.identify)
    truth = None
    if (campaign / "truth.csv").is_file():
        truth = pd.read_csv(campaign / "truth.csv", index_col=0)
    t = time.perf_counter()
    progress("internal gains and forecasts")
    study, figs = forecast_study(fitted, data, truth=truth, seed=seed)
    timings["gains_and_forecasts"] = time.perf_counter() - t
    # the model file the service and `zonecast forecast` use: identified parameters and
    # the fixed weekly profile of the training weeks
    zones = list(site.zones)
    prof = figs["fig2"]["profile_w_m2"]
    model_file = pipe.write_model_file(
        out / "model.json",
        weekly_profile={"zones": zones, "values": [[prof[z][b] for z in zones]
                                                   for b in range(len(prof[zones[0]]))]},
        extra={"profile_weeks": study["split"]["train_starts"]})
    if service:
        t = time.perf_counter()
        progress("service check: the online estimator's day-ahead forecasts")
        weather = _weather_forecasts(campaign, seed, weather_error, progress)
        svc = service_check(model_file, campaign / "telemetry.csv", data, seed,
                            weather=weather)
        study["table3"].update(svc["table3"])
        study["horizon_rms"].update(svc["horizon_rms"])
        study.setdefault("coverage_90", {}).update(
            {f"{k}_calibrated": v for k, v in svc["coverage_90"].items()})
        study["service_input_attribution"] = svc["attribution"]
        study["service_weather_error"] = weather_error
        timings["service_check"] = time.perf_counter() - t
    timings["total"] = time.perf_counter() - t0
    pinned = set(ident.at_bounds())
    res = Results(seed=seed,
                  parameters={n: {"value": float(v), "unit": u, "stderr": float(s),
                                  "bounds": bd, "at_bound": n in pinned}
                              for n, v, u, s, bd in zip(ident.param_names, ident.params,
                                                        ident.units, ident.stderr, ident.bounds)},
                  identification={**ident.to_dict(), "weekend_gains_asked": weekend_gains,
                                  "site_meters": bool(site.points.power),
                                  "reheat_leak": None if leak is None else {
                                      z: {"k": float(leak.k[j]),
                                          "fitted": float(leak.fitted[j]),
                                          "stderr": (float(leak.stderr[j])
                                                     if np.isfinite(leak.stderr[j]) else None)}
                                      for j, z in enumerate(site.zones)}},
                  table2={"training": ident.train_rms, "validation": ident.validation_rms},
                  table2_window_solar_air=None if ident_air is None else
                  {"training": ident_air.train_rms, "validation": ident_air.validation_rms},
                  model_options=model_options_dict(fitted.structure.options),
                  table3=study["table3"], horizon_rms=study["horizon_rms"],
                  gains_truth=study.get("gains_truth") or {},
                  coverage_90=study.get("coverage_90"),
                  service_input_attribution=study.get("service_input_attribution"),
                  service_weather_error=study.get("service_weather_error"),
                  split={"identification": {"train": ident.train_weekends,
                                            "validation": ident.validation_weekends},
                         "gains": study.get("split")},
                  timings_s={k: round(v, 1) for k, v in timings.items()})
    (out / "results.json").write_text(res.model_dump_json(indent=2))
    figures = []
    sims = weekend_simulations(ident.model, data,
                               ident.train_weekends + ident.validation_weekends,
                               window=ident.window,
                               f_ig=_daytime_gains(ident.weekend_gains, ident, data, pipe),
                               x0_gains=pipe.x0_gains, x0_window=ident.x0_window,
                               x0_offset=ident.x0_offset())
    roles = {**{d: "training" for d in ident.train_weekends},
             **{d: "validation" for d in ident.validation_weekends}}
    plot_weekends(sims, roles, list(site.zones), out / "fig1_identification.png",
                  gains=("the fitted weekend gains"
                         if ident.weekend_gains in ("daytime", "metered")
                         else "f_IG = 0"))
    figures.append("fig1_identification.png")
    plot_gains(figs["fig2"], list(site.zones), out / "fig2_internal_gains.png")
    figures.append("fig2_internal_gains.png")
    plot_horizon(res.horizon_rms, list(site.zones), out / "fig3_horizon_rms.png")
    figures.append("fig3_horizon_rms.png")
    week = figs["week"]
    plot_week(week, zones, ["fixed", "dayahead"],
              f"Fig. 4: 24-h forecasts issued at local midnight, validation week of "
              f"{week['start']} (fixed profile and day-ahead online f_IG)",
              out / "fig4_week_fixed.png")
    figures.append("fig4_week_fixed.png")
    plot_week(week, zones, ["online_paper"],
              f"Fig. 5: predictions with online f_IG (paper section 5 reading), validation "
              f"week of {week['start']}", out / "fig5_week_online.png")
    figures.append("fig5_week_online.png")
    write_report(res, out, figures, zones)
    return res
