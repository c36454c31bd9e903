"""The paper's evaluation protocol on a data set (sections 4-B and 5, Tables 2 and 3): the
week split, internal gains per training week, 24-h forecasts at every local midnight of the
validation weeks, the online predictions, interval coverage, the gains-vs-truth check, and
the figure data of ``zonecast reproduce``.

The numerics it runs live in :mod:`~zonecast.estimator.forecast` (profile, filter,
forecasts, coverage) and :mod:`~zonecast.estimator.internal_gains`; this module only
composes them into the study and returns JSON-ready numbers.
"""

from __future__ import annotations

import time

import numpy as np
import pandas as pd
from zonecast.estimator.constants import HORIZON, SIGMA_AIR_FORECAST
from zonecast.estimator.dataset import ModelData
from zonecast.estimator.evaluate import horizon_rms, rms_by_zone
from zonecast.estimator.forecast import (
    WeekTrack,
    _nanmean0,
    coverage,
    coverage_halfwidth,
    empirical_halfwidth,
    fixed_profile,
    issue_forecast,
    issue_rows,
    online_paper_predictions,
    track_week,
    week_split,
    zone_floor_area,
)
from zonecast.estimator.gains import DayAheadGains, fit_weekly_profile
from zonecast.estimator.internal_gains import truth_column, truth_correlation, zone_gain_heat
from zonecast.estimator.model import BilinearModel

__all__ = ["TRUTH_PARTS", "forecast_study", "gains_truth"]


TRUTH_PARTS = ("people", "lights", "equipment", "reheat")


def gains_truth(model: BilinearModel, data: ModelData, tracks: list[WeekTrack],
                truth: pd.DataFrame) -> dict:
    """Per zone r and scale of the estimated gains heat a_floor (c_IG + f_IG) [W] against the
    true people (sensible, :func:`truth_column`) + lights + equipment + reheat heat, and each
    part alone (issue item 5).

    When the boxes' discharge air is measured (``data.reheat`` not all zero) reheat is a
    known input of the model, not part of f_IG, and the total leaves it out."""
    rows = np.concatenate([t.rows for t in tracks])
    f = np.concatenate([t.track.f_ig for t in tracks])
    est = zone_gain_heat(f, model.params.c_ig, zone_floor_area(model))
    tr = truth.copy()
    tr.index = pd.to_datetime(tr.index, utc=True)
    tr = tr.reindex(data.times[rows])
    reheat_known = bool(np.any(data.reheat))
    out = {}
    for j, z in enumerate(data.zones):
        parts = {p: tr.get(truth_column(tr.columns, p, f"zone:{z}"),
                           pd.Series(np.nan, index=tr.index)).to_numpy(float)
                 for p in TRUTH_PARTS}
        in_total = [p for p in TRUTH_PARTS if not (p == "reheat" and reheat_known)]
        total = np.sum([np.nan_to_num(parts[p]) for p in in_total], axis=0)
        res = {"total": truth_correlation(est[:, j], total)}
        res.update({p: truth_correlation(est[:, j], parts[p]) for p in TRUTH_PARTS})
        out[z] = {k: {"r": v["r"], "scale": v["scale"]} for k, v in res.items()}
    return out


def _clean(obj):
    """JSON-ready: NaN -> None, numpy scalars -> float."""
    if isinstance(obj, dict):
        return {k: _clean(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_clean(v) for v in obj]
    if isinstance(obj, float | np.floating):
        return None if not np.isfinite(obj) else float(obj)
    if isinstance(obj, np.integer):
        return int(obj)
    return obj


def forecast_study(model: BilinearModel, data: ModelData, truth: pd.DataFrame | None = None,
                   seed: int = 0, *, dayahead: DayAheadGains | None = None,
                   sigma_air_forecast: float = SIGMA_AIR_FORECAST) -> tuple[dict, dict]:
    """Paper sections 4-B and 5 on a campaign: profile, forecasts, intervals, truth check.

    Returns
    -------
    results : dict (JSON-ready)
        ``split``, ``table3`` {fixed, online_paper, online_paper_validation, dayahead,
        persistence, fixed_kf0: zone -> RMS [K] + mean} (``fixed_kf0``: the fixed forecast
        from the f_IG = 0 filter, a sensitivity), ``horizon_rms`` {method -> zone -> list over
        leads 15 min ... 24 h}, ``coverage_90`` {fixed, dayahead: zone -> fraction + all;
        ``*_empirical``: the same with :func:`empirical_halfwidth` of the training weeks},
        ``interval_halfwidth_90`` (zone -> half-width [K] per lead),
        ``gains_truth`` (zone -> part -> {r, scale}; empty without ``truth``), ``seed``,
        ``seconds``.
    figures : dict (JSON-ready)
        ``fig2``: per zone, the temperature increase C Gamma_IG (c_IG + f_IG,w) [K per
        step] on the 672 time-of-week bins for each training week and their mean;
        ``fig3``: horizon RMS per method (same as results); ``week``: the first validation
        week's measured zone temperatures with the 24-h forecasts (fixed, day-ahead) laid
        end to end per issue day and the paper's online one-step predictions (figures 4
        and 5); ``lead_minutes``.
    """
    t0 = time.perf_counter()
    zones = data.zones
    split = week_split(data, seed)
    weeks = split["weeks"]
    tracks = {w["index"]: track_week(model, data, w["rows"]) for w in weeks}
    train = [tracks[i] for i in split["train"]]
    profile = fixed_profile(data, train)
    halfwidth = empirical_halfwidth(model, data, train)

    # paper section 5 reading: one-step-ahead predictions, all weeks and validation weeks
    def online(idx):
        rows, preds = zip(*(online_paper_predictions(model, tracks[i]) for i in idx))
        rows, preds = np.concatenate(rows), np.concatenate(preds)
        return rms_by_zone(preds, data.y[rows], zones)

    table3 = {"online_paper": online([w["index"] for w in weeks]),
              "online_paper_validation": online(split["validation"])}

    methods = ("fixed", "dayahead", "persistence")
    preds = {m: [] for m in (*methods, "fixed_kf0")}
    stds, meas = [], []
    # figures 4 and 5: the first validation week, forecasts laid end to end per day
    w0 = split["validation"][0]
    a0, b0 = weeks[w0]["rows"]
    week_fc = {m: np.full((b0 - a0, len(zones)), np.nan) for m in ("fixed", "dayahead")}
    for i in split["validation"]:
        for r in issue_rows(data, weeks[i]["rows"]):
            fc = issue_forecast(model, data, r, profile, methods, dayahead=dayahead,
                                sigma_air_forecast=sigma_air_forecast)
            # sensitivity: the fixed forecast from the f_IG = 0 filter (as kalman_state)
            fc["fixed_kf0"] = issue_forecast(model, data, r, profile, ("fixed",),
                                             filter_prior="zero", intervals=False)["fixed"]
            ymeas = np.full((HORIZON, len(zones)), np.nan)
            stop = min(r + 1 + HORIZON, weeks[i]["rows"][1])
            ymeas[:stop - r - 1] = data.y[r + 1:stop]
            pad = np.full((HORIZON, len(zones)), np.nan)
            for m, lst in preds.items():
                p = pad.copy()
                p[:len(fc[m].mean)] = fc[m].mean
                lst.append(p)
            if i == w0:
                for m, wf in week_fc.items():
                    n_ = min(len(fc[m].mean), b0 - r - 1)
                    wf[r + 1 - a0:r + 1 - a0 + n_] = fc[m].mean[:n_]
            s = pad.copy()
            s[:len(fc["fixed"].std)] = fc["fixed"].std
            stds.append(s)
            meas.append(ymeas)
    meas_a, std_a = np.array(meas), np.array(stds)
    hrms = {}
    cov = {}
    for m, lst in preds.items():
        pa = np.array(lst)
        table3[m] = rms_by_zone(pa.reshape(-1, len(zones)), meas_a.reshape(-1, len(zones)), zones)
        hrms[m] = horizon_rms(pa, meas_a, zones)
        if m in ("fixed", "dayahead"):
            cov[m] = coverage(pa, std_a, meas_a, zones)
            cov[f"{m}_empirical"] = coverage_halfwidth(pa, halfwidth, meas_a, zones)

    # figure 2: temperature increase due to internal gains per training week and mean
    step = data.times[1] - data.times[0]
    per_week = []
    for t in train:
        rise = np.einsum("kij,kj->ki", t.track.cb, t.track.f_ig + model.params.c_ig)
        per_week.append(fit_weekly_profile(data.times[t.rows], rise, data.timezone, step=step).values)
    fig2 = {z: {"weeks": [w[:, j].tolist() for w in per_week],
                "mean": _nanmean0(np.array(per_week)[..., j]).tolist()}
            for j, z in enumerate(zones)}
    fig2["week_starts"] = split["train_starts"]
    fig2["profile_w_m2"] = {z: profile.values[:, j].tolist() for j, z in enumerate(zones)}

    results = {
        "split": {**{k: split[k] for k in ("train", "validation", "train_starts",
                                           "validation_starts", "seed")},
                  "train_segments": [weeks[i]["segment"] for i in split["train"]],
                  "validation_segments": [weeks[i]["segment"] for i in split["validation"]]},
        "table3": table3,
        "horizon_rms": hrms,
        "coverage_90": cov,
        "interval_halfwidth_90": {z: halfwidth[:, j].tolist() for j, z in enumerate(zones)},
        "gains_truth": ({} if truth is None else
                        gains_truth(model, data, list(tracks.values()), truth)),
        "n_forecasts": len(meas),
        "seed": int(seed),
    }
    results["seconds"] = time.perf_counter() - t0
    rows5, pred5 = online_paper_predictions(model, tracks[w0])
    online_week = np.full((b0 - a0, len(zones)), np.nan)
    keep = (rows5 >= a0) & (rows5 < b0)
    online_week[rows5[keep] - a0] = pred5[keep]
    week = {"start": weeks[w0]["start"],
            "times": [t.isoformat() for t in data.local_times()[a0:b0]],
            "measured": {z: data.y[a0:b0, j].tolist() for j, z in enumerate(zones)},
            "fixed": {z: week_fc["fixed"][:, j].tolist() for j, z in enumerate(zones)},
            "dayahead": {z: week_fc["dayahead"][:, j].tolist() for j, z in enumerate(zones)},
            "online_paper": {z: online_week[:, j].tolist() for j, z in enumerate(zones)}}
    figures = {"fig2": fig2, "fig3": hrms, "week": week,
               "lead_minutes": [15 * (h + 1) for h in range(HORIZON)]}
    return _clean(results), _clean(figures)
