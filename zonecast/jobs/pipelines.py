"""The CLI's pipelines: check a site's data, build its model, identify it, forecast from a
model file. Each takes paths, returns what the command prints, and leaves printing and
progress display to the CLI (:mod:`zonecast.cli`)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd

from zonecast.estimator.constants import HORIZON, STEP
from zonecast.estimator.forecast import Forecast
from zonecast.estimator.identify import IdentificationResult
from zonecast.estimator.idf import Building
from zonecast.estimator.model import BilinearModel, write_model_summary
from zonecast.estimator.pipeline import (
    OPERATING_FILMS_MODE,
    REHEAT_LEAK,
    Pipeline,
    check_reheat_leak,
    identify_operating_films,
)
from zonecast.estimator.rc.network import ModelOptions
from zonecast.estimator.rc.parameters import ParameterSet
from zonecast.estimator.site import Site, parse_step
from zonecast.estimator.telemetry import Telemetry

__all__ = ["IdentifyOutcome", "build_model", "check_site", "forecast_at", "identify_site"]

Progress = Callable[[str], None]


def _quiet(_: str) -> None:
    return None


def check_site(site: Path, data: Path) -> tuple[Site, Telemetry]:
    """Validate a site description and its telemetry (raises ``ValueError`` naming what to
    fix)."""
    pipe = Pipeline.from_site(site)
    return pipe.site, pipe.telemetry(data)


def build_model(site: Path, out: Path, *, params: str = "start",
                energyplus_dir: Path | None = None,
                window_solar: str = ModelOptions.window_solar) -> tuple[Site, BilinearModel, Building]:
    """Build a site's bilinear RC model (paper section 3) and write its summary (JSON) and
    matrices (``out`` with ``.npz``). ``params``: ``start`` or ``paper`` (Table 1)."""
    pipe = Pipeline.from_site(site, options=ModelOptions(window_solar=window_solar),
                              energyplus_dir=energyplus_dir)
    if params == "start":
        values = None
    elif params == "paper":
        paper = ParameterSet.paper_table1()
        if sorted(paper.zones) != sorted(pipe.site.zones):
            raise ValueError(f"--params paper needs the paper's zones {list(paper.zones)}; "
                             f"this site has {list(pipe.site.zones)}")
        values = {n: paper[n] for n in paper.param_names}
    else:
        raise ValueError(f"--params {params}: use 'start' or 'paper'")
    model = pipe.model(values)
    write_model_summary(model, out, out.with_suffix(".npz"))
    return pipe.site, model, pipe.building()


@dataclass
class IdentifyOutcome:
    """What ``zonecast identify`` did."""

    result: IdentificationResult
    model_file: Path
    profile_weeks: list[str] = field(default_factory=list)
    #: the site maps lights and plug-load meters (``points.power``)
    metered: bool = False
    #: zone -> k of :meth:`Pipeline.fit_reheat_leak` (None: not fitted)
    reheat_leak: dict[str, float] | None = None


def identify_site(site: Path, data: Path, out: Path, *, train: list[str] | None = None,
                  validate: list[str] | None = None, starts: int = 1,
                  profile_weeks: bool = True, window_solar: str = ModelOptions.window_solar, seed: int = 0,
                  priors: bool = True, sigma_e: float = 0.3, window: str = "weekend",
                  infiltration: str = ModelOptions.infiltration, weekend_gains: bool | str = "auto",
                  ground: str = ModelOptions.ground, shading: str = ModelOptions.shading, return_air: str = ModelOptions.return_air,
                  roof_solar: str = ModelOptions.roof_solar, sky: str = ModelOptions.sky,
                  interior_radiation: str = ModelOptions.interior_radiation, films: str | None = None,
                  internal_gains: str = ModelOptions.internal_gains, window_angle: str = ModelOptions.window_angle,
                  roof_exterior: str = ModelOptions.roof_exterior, envelope_radiation: str = ModelOptions.envelope_radiation,
                  solar_enclosure: str = ModelOptions.solar_enclosure, adiabatic: str = ModelOptions.adiabatic,
                  layers: str = ModelOptions.layers, internal_mass: str = ModelOptions.internal_mass,
        inside_convection: str = ModelOptions.inside_convection,
                  roof_inside: str = ModelOptions.roof_inside,
                  progress: Progress = _quiet,
                  x0_profile_days: int | None = None,
                  x0_meters: bool | str = "auto",
                  constant_gains: str = "fitted",
                  x0_offset_sd: float | None = None,
                  day_scale_sd: float | None = None,
                  positive_priors: str = "log",
                  operating_films: str = OPERATING_FILMS_MODE,
                  reheat_leak: str = REHEAT_LEAK) -> IdentifyOutcome:
    """Identify the 13 parameters (paper section 4-A), estimate the weekly internal-gains
    profile (4-B) from every whole week, and write the model file. ``infiltration``,
    ``ground``, ``shading``, ``return_air``, ``roof_solar``, ``sky``,
    ``interior_radiation``, ``internal_gains``, ``window_angle``, ``roof_exterior``,
    ``envelope_radiation``, ``solar_enclosure``, ``adiabatic``, ``layers``,
    ``internal_mass``, ``inside_convection``, ``roof_inside``: as
    :class:`~zonecast.estimator.rc.network.ModelOptions`;
    ``weekend_gains``, ``films``, ``x0_profile_days``, ``x0_meters``, ``x0_offset_sd``,
    ``day_scale_sd``, ``constant_gains``,
    ``positive_priors``: as :meth:`~zonecast.estimator.pipeline.Pipeline.identify`;
    ``operating_films``: ``"none"`` or ``"natural"`` as ``Pipeline.identify``, ``"auto"`` (the
    default) :meth:`~zonecast.estimator.pipeline.Pipeline.fit_operating_films` on the
    profile's weeks before the reheat leak; ``reheat_leak``
    ``"added"`` or ``"from_faces"``: :meth:`~zonecast.estimator.pipeline.Pipeline.fit_reheat_leak`
    on the profile's weeks before the profile; ``"none"``: the reheat heat as measured."""
    pipe = Pipeline.from_site(site, options=ModelOptions(window_solar=window_solar,
                                                         infiltration=infiltration,
                                                         ground=ground, shading=shading,
                                                         return_air=return_air,
                                                         roof_solar=roof_solar, sky=sky,
                                                         interior_radiation=interior_radiation,
                                                         internal_gains=internal_gains,
                                                         window_angle=window_angle,
                                                         roof_exterior=roof_exterior,
                                                         envelope_radiation=envelope_radiation,
                                                         solar_enclosure=solar_enclosure,
                                                         adiabatic=adiabatic,
                                                         layers=layers,
                                                         internal_mass=internal_mass,
                                                   inside_convection=inside_convection,
                                                   roof_inside=roof_inside))
    d = pipe.data(data)
    res = pipe.identify(d, train, validate, n_starts=starts, seed=seed, priors=priors,
                        sigma_e=sigma_e, window=window, weekend_gains=weekend_gains,
                        films=films, progress=lambda m: progress(f"identification: {m}"),
                        x0_profile_days=x0_profile_days, x0_offset_sd=x0_offset_sd,
                        day_scale_sd=day_scale_sd, positive_priors=positive_priors,
                        operating_films=identify_operating_films(operating_films),
                        x0_meters=x0_meters, constant_gains=constant_gains)
    check_reheat_leak(reheat_leak)
    if profile_weeks:
        if operating_films == "auto":
            pipe.fit_operating_films(d, progress=progress)
        if reheat_leak != "none":
            pipe.fit_reheat_leak(d, progress=progress,
                                 from_faces=reheat_leak == "from_faces")
        pipe.weekly_profile(d, progress=lambda m: progress(f"weekly internal-gains profile: {m}"))
    out.parent.mkdir(parents=True, exist_ok=True)
    path = pipe.write_model_file(out, extra={"profile_weeks": pipe.profile_weeks})
    leak = None if pipe.reheat_leak is None else dict(zip(pipe.site.zones,
                                                          map(float, pipe.reheat_leak.k)))
    return IdentifyOutcome(res, path, pipe.profile_weeks, bool(pipe.site.points.power), leak)


def forecast_at(model: Path, data: Path, at: str, horizon: str = "24h"
                ) -> tuple[Forecast, int, pd.DataFrame]:
    """The forecast the service would issue at ``at`` (ISO-8601 with offset), computed
    offline from recorded telemetry; returns it, the number of steps asked for, and a table
    (time, zone, mean and 90 % bounds)."""
    t = pd.Timestamp(at)
    if t.tzinfo is None:
        raise ValueError(f"--at {at}: give a UTC offset, e.g. 2015-05-12T00:00:00-07:00")
    steps = int(parse_step(horizon.strip()) // STEP)
    if not 1 <= steps <= HORIZON:
        raise ValueError(f"--horizon {horizon}: between 15min and 24h")
    pipe = Pipeline.from_model_file(model)
    (f,) = pipe.forecast(data / "telemetry.csv" if data.is_dir() else data, [t]).values()
    lo, hi = f.lower[:steps], f.upper[:steps]
    rows = [{"time": tt.isoformat(), "zone": z, "mean_degC": f.mean[k, j], "p05_degC": lo[k, j],
             "p95_degC": hi[k, j]} for k, tt in enumerate(f.times[:steps])
            for j, z in enumerate(f.zones)]
    return f, steps, pd.DataFrame(rows)
