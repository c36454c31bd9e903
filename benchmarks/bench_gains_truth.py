"""Where the internal-gains estimate's error lies, against the testbed's truth (issue 13).

For each member: the per-step f_IG least squares of every week (as ``zonecast reproduce``'s
gains-vs-truth check: x(0) from the week's first day, then
:func:`~zonecast.estimator.internal_gains.track_gains`), the estimated gains heat
a_floor (c_IG + f_IG) [W] per zone against the true people + lights + equipment heat [W].
Prints per zone

* ``r``: Pearson r at 15 min (the figure of the issue's must), and ``r_1h`` on centred
  1-h means of the estimate (how much is step-to-step noise);
* ``r − k Q``: r of the estimate less k Q_reheat (what r would be without that part);
* ``b``, ``k``: the least-squares coefficients of estimate ~ a + b truth + k Q_reheat with
  Q_reheat = c_p sum_j u_j r_j [W], the zone's measured reheat heat. The model is given
  Q_reheat as a known input, so a perfect model has k = 0; ``b`` is the share of the true
  gains the per-step estimate sees within its step (their convective part, scaled by how
  the model's air node responds to heat);
* ``k_prior``, ``b_prior``: the same with the parameters at their priors' means (the
  description's physics; c_IG as fitted), which tells fit from structure.

``--explain`` adds a second table: the estimate regressed on the true gains and on what a
perfect model would not let into it, by group, and each group's *unique* share of the
estimate's variance (R² lost when that group alone is left out):

* ``lag``: the true gains' 1-h means 1, 2 and 4 h earlier (the radiant part reaching the air
  late);
* ``reheat``: Q_reheat as above; ``supply``: the boxes' supply-air heat c_p sum_j u_j (T_s -
  T_z) without the reheat; ``envelope``: T_a - T_z; ``solar``: the five solar columns
  (four facades and horizontal);
* ``dy``: the zone temperature's change over the step (heat the model's air node and its
  coupling to the room's mass ask for when the air warms or cools);

and ``r clean``: r of the estimate less the fitted reheat, supply, envelope, solar and dy
parts (what r would be if the model let none of them into the estimate).

    python benchmarks/bench_gains_truth.py --models DIR --family DIR [--extra CAMPAIGN ...]
                                           [--only NAME ...]

``--models`` holds ``<name>/model.json`` (``zonecast identify --out``
``DIR/<name>/model.json``, or a ``bench_family.py --out`` folder); campaigns are
``--family/<name>`` (with its ``index.json`` for the roles) or the ``--extra`` folders.
docs/identification.md "The gains estimate against the truth".
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # small matrices: threads only contend

import argparse
import itertools
import json
import platform
import statistics
import time
from pathlib import Path

import numpy as np
import pandas as pd
from zonecast.estimator.forecast import track_week, week_split, zone_floor_area
from zonecast.estimator.internal_gains import truth_column, truth_correlation, zone_gain_heat
from zonecast.estimator.pipeline import Pipeline
from zonecast.estimator.rc.network import CP_AIR  # the model's c_p of air [J/(kg K)]

PARTS = ("people", "lights", "equipment")


def centred_mean(x: np.ndarray, rows: np.ndarray, width: int) -> np.ndarray:
    """Centred moving mean of ``x`` over ``width`` rows within each run of consecutive
    ``rows`` (weeks are not joined)."""
    out = np.empty_like(x)
    cuts = np.r_[0, np.nonzero(np.diff(rows) != 1)[0] + 1, len(rows)]
    for a, b in itertools.pairwise(cuts):
        out[a:b] = pd.Series(x[a:b]).rolling(width, center=True, min_periods=1).mean()
    return out


def regress(est: np.ndarray, true: np.ndarray, reheat: np.ndarray) -> tuple[float, float]:
    """(b, k) of est ~ a + b true + k reheat by least squares over finite rows."""
    ok = np.isfinite(est) & np.isfinite(true)
    x = np.c_[np.ones(ok.sum()), true[ok], reheat[ok]]
    coef, *_ = np.linalg.lstsq(x, est[ok], rcond=None)
    return float(coef[1]), float(coef[2])


EXPLAIN = ("lag", "reheat", "supply", "envelope", "solar", "dy")


def _r2(x: np.ndarray, y: np.ndarray) -> tuple[float, np.ndarray]:
    coef, *_ = np.linalg.lstsq(x, y, rcond=None)
    return 1.0 - float(np.var(y - x @ coef) / np.var(y)), coef


def explain(est: np.ndarray, true: np.ndarray, groups: dict[str, list[np.ndarray]]) -> dict:
    """R² of est ~ 1 + true + all groups; each group's unique R² share; r of est less the
    fitted non-gain groups (all but ``lag``). Rows with a non-finite value are left out."""
    cols = [true] + [a for g in EXPLAIN for a in groups[g]]
    ok = np.isfinite(est) & np.all(np.isfinite(np.column_stack(cols)), axis=1)
    one = np.ones(ok.sum())
    full, coef = _r2(np.column_stack([one] + [c[ok] for c in cols]), est[ok])
    out = {"R2": full}
    for g in EXPLAIN:
        rest = [true] + [a for h in EXPLAIN if h != g for a in groups[h]]
        out[g] = full - _r2(np.column_stack([one] + [c[ok] for c in rest]), est[ok])[0]
    part, i = np.zeros(ok.sum()), 2
    for g in EXPLAIN:
        for a in groups[g]:
            if g != "lag":
                part += coef[i] * a[ok]
            i += 1
    out["r_clean"] = float(np.corrcoef(est[ok] - part, true[ok])[0, 1])
    return out


def _lagged_hour_mean(x: np.ndarray, rows: np.ndarray, lag: int) -> np.ndarray:
    """1-h mean of ``x`` ending ``lag`` rows earlier, within each run of consecutive rows
    (NaN where it would reach into the previous week)."""
    out = np.full_like(x, np.nan, dtype=float)
    cuts = np.r_[0, np.nonzero(np.diff(rows) != 1)[0] + 1, len(rows)]
    for a, b in itertools.pairwise(cuts):
        out[a:b] = pd.Series(x[a:b]).shift(lag).rolling(4).mean().to_numpy()
    return out


def member(model_file: Path, campaign: Path, with_explain: bool = False) -> dict:
    """Per zone r, r_1h, b, k (fitted) and b, k with the priors' means."""
    pipe = Pipeline.from_model_file(model_file)
    data = pipe.data(campaign)
    truth = pd.read_csv(campaign / "truth.csv", index_col=0)
    truth.index = pd.to_datetime(truth.index, utc=True)
    doc = json.loads(model_file.read_text())
    prior = dict(doc["parameters"])
    prior.update({k: v["mean"] for k, v in doc["identification"].get("prior", {}).items()
                  if not k.startswith("c_IG")})
    weeks = week_split(data, 0)["weeks"]
    out: dict[str, dict] = {}
    for label, params in (("fit", None), ("prior", prior)):
        model = pipe.model(params)
        tracks = [track_week(model, data, w["rows"]) for w in weeks]
        rows = np.concatenate([t.rows for t in tracks])
        f = np.concatenate([t.track.f_ig for t in tracks])
        est = zone_gain_heat(f, model.params.c_ig, zone_floor_area(model))
        tr = truth.reindex(data.times[rows])
        # the site's VAV boxes only: ground contact enters the model as pseudo-boxes
        box_zone = np.where([b in pipe.site.boxes for b in model.structure.boxes],
                            model.structure.state_zones()[np.asarray(
                                model.structure.room_of_box)], -1)
        q_box = CP_AIR * data.u[rows] * data.reheat[rows]
        for j, z in enumerate(data.zones):
            true = np.sum([np.nan_to_num(tr.get(truth_column(tr.columns, p, f"zone:{z}"),
                                                pd.Series(np.nan, index=tr.index))
                                         .to_numpy(float)) for p in PARTS], axis=0)
            q = q_box[:, box_zone == j].sum(axis=1)
            b, k = regress(est[:, j], true, q)
            res = out.setdefault(z, {})
            if label == "fit" and with_explain:
                y, v, u = data.y[rows, j], data.v[rows], data.u[rows][:, box_zone == j]
                dy = np.r_[np.nan, np.diff(y)]
                dy[np.r_[True, np.diff(rows) != 1]] = np.nan  # not across weeks
                res["explain"] = explain(est[:, j], true, {
                    "lag": [_lagged_hour_mean(true, rows, L) for L in (4, 8, 16)],
                    "reheat": [q],
                    "supply": [CP_AIR * (u * (v[:, [1]] - y[:, None])).sum(axis=1)],
                    "envelope": [v[:, 0] - y],
                    "solar": [v[:, c] for c in range(2, 7)],
                    "dy": [dy]})
            if label == "fit":
                res["r"] = truth_correlation(est[:, j], true)["r"]
                res["r_1h"] = truth_correlation(centred_mean(est[:, j], rows, 4), true)["r"]
                res["b"], res["k"] = b, k
                # what r would be without the reheat leaking into the estimate
                res["r_no_rh"] = truth_correlation(est[:, j] - k * q, true)["r"]
                res["reheat_w"] = float(q.mean())
            else:
                res["b_prior"], res["k_prior"] = b, k
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--models", type=Path, required=True)
    ap.add_argument("--family", type=Path)
    ap.add_argument("--extra", type=Path, nargs="*", default=[])
    ap.add_argument("--only", nargs="*")
    ap.add_argument("--explain", action="store_true",
                    help="also the estimate's unique variance shares of the true gains' lags, "
                         "reheat, supply air, envelope, solar and the air's change, and r "
                         "without the non-gain parts (a second table)")
    a = ap.parse_args(argv)
    members: list[tuple[str, str, Path]] = []
    if a.family is not None:
        index = json.loads((a.family / "index.json").read_text())
        members += [(m["name"], m["role"], a.family / m["name"]) for m in index["members"]]
    members += [(p.name, "third_party", p) for p in a.extra]
    if a.only:
        members = [m for m in members if m[0] in a.only]
    if not members:
        raise SystemExit("no members: give --family and/or --extra")
    print(f"# bench_gains_truth on {platform.machine()}, {os.cpu_count()} cores, "
          f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}")
    print("| member | role | r | r 1 h | r − k Q | b | k | b prior | k prior | reheat W |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    by_role: dict[str, list[dict]] = {}
    explained: list[tuple[str, str, dict]] = []
    for name, role, campaign in members:
        model_file = a.models / name / "model.json"
        if not model_file.is_file():
            raise SystemExit(f"{model_file} missing: run zonecast identify --out {model_file}")
        t0 = time.perf_counter()
        zones = member(model_file, campaign, a.explain)
        if a.explain:
            explained.append((name, role, {k: statistics.median(v["explain"][k]
                                                                for v in zones.values())
                                           for k in ("R2",) + EXPLAIN + ("r_clean",)}))
        med = {key: statistics.median(v[key] for v in zones.values())
               for key in ("r", "r_1h", "r_no_rh", "b", "k", "b_prior", "k_prior",
                            "reheat_w")}
        by_role.setdefault(role, []).append(med)
        print(f"| {name} | {role} | {med['r']:.2f} | {med['r_1h']:.2f} | {med['r_no_rh']:.2f} | "
              f"{med['b']:.2f} | "
              f"{med['k']:.2f} | {med['b_prior']:.2f} | {med['k_prior']:.2f} | "
              f"{med['reheat_w']:.0f} |  ({time.perf_counter() - t0:.1f} s; zone medians)",
              flush=True)
    for role, meds in by_role.items():
        print(f"| **median {role}** ({len(meds)}) | | "
              + " | ".join(f"{statistics.median(m[k] for m in meds):.2f}"
                           for k in ("r", "r_1h", "r_no_rh", "b", "k", "b_prior", "k_prior"))
              + " | |")
    if explained:
        keys = ("R2",) + EXPLAIN + ("r_clean",)
        print("\nUnique shares of the estimate's variance (zone medians; R² of the full "
              "regression first, r without the non-gain parts last):\n")
        print("| member | role | R² all | " + " | ".join(EXPLAIN) + " | r clean |")
        print("|---|---|" + "---|" * (len(keys)))
        for name, role, med in explained:
            print(f"| {name} | {role} | " + " | ".join(f"{med[k]:.3f}" for k in keys) + " |")
        for role in dict.fromkeys(r for _, r, _ in explained):
            meds = [m for _, r, m in explained if r == role]
            print(f"| **median {role}** ({len(meds)}) | | "
                  + " | ".join(f"{statistics.median(m[k] for m in meds):.3f}" for k in keys)
                  + " |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
