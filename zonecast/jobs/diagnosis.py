"""`zonecast diagnose`: run the diagnosis on a site's data and write diagnosis.json, plots and
diagnosis.md (the numerics are in :mod:`zonecast.estimator.diagnose`)."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from zonecast.estimator.dataset import model_data
from zonecast.estimator.diagnose import (
    CONFIDENCE,
    MIN_SCORE,
    Diagnosis,
    DiagnosisError,
    diagnose,
    furniture_rebuilder,
    load_reference,
)
from zonecast.estimator.effects import SPECS
from zonecast.estimator.pipeline import Pipeline
from zonecast.estimator.site import load_site
from zonecast.estimator.telemetry import load_telemetry


def run(model_path: Path, data_path: Path, out: Path, *, site_path: Path | None = None,
        seed: int = 0, gains: str = "profile", reference: Path | None = None,
        progress: Callable[[str], None] | None = None) -> Diagnosis:
    """Load the model file and telemetry, diagnose, write ``out``. ``reference``: the
    ``diagnosis.json`` of a period known to be clean; its confident effects are added to the
    base model (:func:`~zonecast.estimator.diagnose.diagnose`)."""
    pipe = Pipeline.from_model_file(model_path)
    site = load_site(site_path) if site_path is not None else pipe.site
    if list(site.zones) != list(pipe.site.zones):
        raise ValueError(f"--site zones {list(site.zones)} differ from the model file's "
                         f"{list(pipe.site.zones)}: diagnose the model of this site")
    tel = load_telemetry(data_path / "telemetry.csv" if data_path.is_dir() else data_path, site)
    model = pipe.model()
    data = model_data(tel, model.room_weights(), facade_azimuths=model.structure.facade_azimuths,
                      scheduled=model.structure.scheduled,
                      shading=model.structure.facade_shading,
                      panes=model.structure.window_panes)
    ref = None
    if reference is not None:
        try:
            doc = json.loads(Path(reference).read_text())
        except (OSError, ValueError) as exc:
            raise ValueError(f"reference diagnosis {reference}: {exc}") from None
        try:
            ref = load_reference(doc, list(site.zones), site.timezone)
        except DiagnosisError as exc:
            raise ValueError(f"reference diagnosis {reference}: {exc}") from None
    setpoint = None
    if site.thermostat is not None:
        setpoint = site.thermostat.heating_setpoint(data.times, site.timezone, data.excitation)
    # the thermal-mass term rebuilds the model with a zone's furniture scaled when the
    # site's EnergyPlus file can be read (else it scales the furniture's nodes alone)
    try:
        building = pipe.building()
    except (OSError, ValueError) as exc:  # no EnergyPlus or no IDF here
        building = None
        if progress:
            progress(f"thermal mass: furniture nodes scaled alone ({exc})")
    mass_model = None if building is None else furniture_rebuilder(
        building, site.zones, {b: box.room for b, box in site.boxes.items()}, model)
    res = diagnose(model, data, seed=seed, gains=gains, reference=ref,
                   heating_setpoint=setpoint, progress=progress, mass_model=mass_model)
    write(res, out, list(site.zones))
    return res


def write(res: Diagnosis, out: Path, zones: list[str]) -> None:
    out.mkdir(parents=True, exist_ok=True)
    (out / "diagnosis.json").write_text(json.dumps(res.to_dict(), indent=1))
    figs = [_plot_where(res, out / "where.png", zones), _plot_effects(res, out / "effects.png")]
    _write_md(res, out, figs)


def _plot_where(res: Diagnosis, path: Path, zones: list[str]) -> str:

    dims = ["zone", "hour_of_day", "lead", "season", "regime", "solar_level",
            "outdoor_temperature", "operation"]
    fc = res.where["forecast"]
    fig = Figure(figsize=(16, 6.5))
    axes = fig.subplots(2, 4)
    for ax, d in zip(axes.flat, dims):
        rows = fc.get(d, [])
        ax.bar(range(len(rows)), [r["rms"] for r in rows], color="tab:blue", label="forecast")
        sim = {r["slice"]: r["rms"] for r in res.where["simulation"].get(d, [])}
        ax.plot(range(len(rows)), [sim.get(r["slice"], np.nan) for r in rows], "o",
                color="tab:red", ms=4, label="simulation")
        ax.set_xticks(range(len(rows)), [r["slice"] for r in rows],
                      rotation=60 if len(rows) > 6 else 20, fontsize=7, ha="right")
        ax.set_title(d.replace("_", " "))
        ax.set_ylabel("RMS [K]")
    axes.flat[0].legend(fontsize=7)
    fig.suptitle("Where the error lies: RMS of measured minus model by slice")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    return path.name


def _plot_effects(res: Diagnosis, path: Path) -> str:

    zones = list(res.per_zone)
    effects = list(SPECS)
    grid = np.array([[next((c.score for c in res.per_zone[z] if c.effect == e), np.nan)
                      for z in zones] for e in effects])
    fig = Figure(figsize=(13, 4.2))
    (a1, a2) = fig.subplots(1, 2)
    im = a1.imshow(np.clip(grid, 0, None), cmap="viridis", aspect="auto")
    a1.set_xticks(range(len(zones)), zones)
    a1.set_yticks(range(len(effects)), effects)
    for i in range(len(effects)):
        for j in range(len(zones)):
            c = next(c for c in res.per_zone[zones[j]] if c.effect == effects[i])
            a1.text(j, i, f"{c.score:.3f}{'*' if c.confident else ''}", ha="center",
                    va="center", fontsize=7, color="w")
    fig.colorbar(im, ax=a1, label="cross-validated share of SSE removed")
    a1.set_title("Effect scores per zone (* confident)")
    names = [c.effect for c in res.ranked]
    before = [c.heldout_rms_before.get("mean", np.nan) for c in res.ranked]
    after = [c.heldout_rms_after.get("mean", np.nan) for c in res.ranked]
    x = np.arange(len(names))
    a2.bar(x - 0.2, before, 0.4, label="before", color="grey")
    a2.bar(x + 0.2, after, 0.4, label="after (effect added)", color="tab:green")
    a2.set_xticks(x, names, rotation=30, ha="right", fontsize=8)
    a2.set_ylabel("held-out forecast RMS, mean of zones [K]")
    lo = np.nanmin(after + before)
    a2.set_ylim(lo * 0.9, None)
    a2.legend(fontsize=8)
    a2.set_title("Held-out weeks (used neither to find nor to fit)")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    return path.name


def _write_md(res: Diagnosis, out: Path, figs: list[str]) -> None:
    d = res.to_dict()
    sp = d["split"]
    L = ["# zonecast diagnose", "",
         (f"Split (seed {sp['seed']}): search and fit on training weeks starting "
         f"{', '.join(sp['train_starts'])}; held out: {', '.join(sp['validation_starts'])}. "
         f"Internal gains in the base model: {res.gains}. Thresholds: confidence >= "
         f"{CONFIDENCE}, cross-validated score >= {MIN_SCORE}. {res.seconds:.0f} s."), ""]
    if res.gains == "reference":
        L += [("Against a reference period: the base model keeps that period's internal-gains "
               "profile" + ("; its confident effects are added as terms: "
                            + "; ".join(f"`{t['effect']}` in {', '.join(t['parameters'])}"
                                        for t in res.reference) if res.reference else "")
               + ". The ranking below is of what is new."), ""]
    elif res.reference:
        L += [("Reference terms added to the base model (the confident effects of a diagnosis "
               "of a clean period; the ranking below is of what is new): "
               + "; ".join(f"`{t['effect']}` in {', '.join(t['parameters'])}"
                           for t in res.reference) + "."), ""]
    conf = [c for c in res.ranked if c.confident]
    if not conf:
        L += [("**No candidate effect explains the error with confidence.** The residuals are "
              "not attributable to any effect in the library at these thresholds."), ""]
    else:
        top = conf[0]
        L += [(f"**Top attribution: `{top.effect}` in {', '.join(top.zones)}** "
              f"(score {top.score:.3f}, confidence {top.confidence:.3f}); held-out mean RMS "
              f"{top.heldout_rms_before['mean']:.3f} -> {top.heldout_rms_after['mean']:.3f} K."), ""]
        if top.tied_with:
            L += [(f"`{top.effect}` ({top.n_params} parameter{'s' if top.n_params > 1 else ''}) "
                   "explains the training residuals as well as "
                   + ", ".join(f"`{e}`" for e in top.tied_with)
                   + " (paired test of the per-day reductions not significant): these data do "
                   "not separate them; it is ranked first as the explanation with the fewest "
                   "parameters. Check it on site (e.g. a reference thermometer, or the "
                   "sensor against the air at the boxes)."), ""]
        helped = [c for c in conf if c.heldout_rms_after["mean"] < c.heldout_rms_before["mean"]]
        if not helped:
            L += [("No confident candidate lowers the held-out RMS: the attribution does not "
                  "generalise to the withheld weeks."), ""]
    L += ["## Ranked effects", "",
          "| rank | effect | zones | variant | parameters | score | confidence | held-out RMS before -> after [K] |",
          "|---|---|---|---|---|---|---|---|"]
    for i, c in enumerate(res.ranked, 1):
        par = ", ".join(f"{z} {v:.3g}" for z, v in c.parameters.items())
        L.append(f"| {i} | {c.effect}{' (confident)' if c.confident else ''} | "
                 f"{', '.join(c.zones)} | {c.variant if c.variant is not None else ''} | "
                 f"{par} {SPECS[c.effect].unit} | {c.score:.3f} | {c.confidence:.3f} | "
                 f"{c.heldout_rms_before['mean']:.3f} -> {c.heldout_rms_after['mean']:.3f} |")
    fwd = res.forward
    if fwd is not None and fwd["steps"]:
        L += ["", "## Forward selection", "",
              ("From the top effect: with the effects above it in the model (refitted together "
               "in every leave-one-week-out fold), which others are still confident; the best "
               "is added next. Scores are shares of the base's training SSE removed beyond the "
               "effects before."), "",
              "| step | effect added | zones | score | confidence | still confident after it |",
              "|---|---|---|---|---|---|"]
        after = fwd["confident_after"]
        for i, st in enumerate(fwd["steps"], 1):
            left = after[i] if i < len(after) else []
            L.append(f"| {i} | {st['effect']} | {', '.join(st['zones'])} | {st['score']:.3f} | "
                     f"{st['confidence']:.3f} | {', '.join(left) or 'none'} |")
    L += ["", "## Where the error lies (slices carrying more than their share)", "",
          "| residual | dimension | slice | RMS [K] | share of error | share of rows |",
          "|---|---|---|---|---|---|"]
    for r in res.where["carriers"]:
        L.append(f"| {r['residual']} | {r['dimension']} | {r['slice']} | {r['rms']:.3f} | "
                 f"{r['share_of_error']:.2f} | {r['share_of_rows']:.2f} |")
    L += ["", "## Per zone, best three effects", ""]
    for z, cs in res.per_zone.items():
        L.append(f"- **{z}**: " + "; ".join(f"{c.effect} {c.score:.3f} ({c.confidence:.2f})"
                                             for c in cs[:3]))
    L += [""] + [f"![{f}]({f})" for f in figs] + [""]
    (out / "diagnosis.md").write_text("\n".join(L))
