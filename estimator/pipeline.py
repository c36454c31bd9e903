"""The pipeline facade: site -> model -> data -> identify -> forecast, in one object.

pvlib's ``ModelChain`` is the anchor: :class:`Pipeline` holds a site and what has been
computed for it, and each step calls the estimator's functions (which stay usable on
their own)::

    pipe = Pipeline.from_site("site.yaml")        # or Pipeline.from_model_file("model.json")
    data = pipe.data("telemetry.csv")             # paper's u, v, y on the model step
    res = pipe.identify(data)                     # paper section 4-A (IdentificationResult)
    prof = pipe.weekly_profile(data)              # paper Eq:fixed_ig (WeeklyProfile)
    pipe.write_model_file("model.json")           # the artefact the service serves
    fc = pipe.forecast("telemetry.csv", [t])      # the streaming estimator's forecasts

The CLI, the jobs (reproduce, diagnosis report), the service's model loader and the
benchmarks call it. Reading the building's EnergyPlus file needs EnergyPlus; a pipeline
made from a model file with a stored structure (:mod:`~zonecast.estimator.artifact`) does
not.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path

import numpy as np
import pandas as pd
from zonecast.estimator import forecast as forecast_module
from zonecast.estimator.artifact import (
    ModelBundle,
    NoiseSettings,
    load_model_file,
    model_options_dict,
    write_model_file,
)
from zonecast.estimator.dataset import ModelData, model_data
from zonecast.estimator.forecast import (
    Forecast,
    fixed_profile,
    track_week,
    whole_weeks,
    zone_floor_area,
)
from zonecast.estimator.gains import ReheatLeak, WeeklyProfile, fit_reheat_leak
from zonecast.estimator.identify import IdentificationResult, excitation_saturdays, identify
from zonecast.estimator.idf import Building, read_building
from zonecast.estimator.inputs_forecast import DayCalendar
from zonecast.estimator.model import BilinearModel
from zonecast.estimator.priors import (
    CONVECTIVE_FILMS,
    OPERATING_FILM_MODES,
    POSITIVE_PRIORS,
    Prior,
    building_priors,
    convective_films,
    operating_film_ratios,
    roof_film_prior,
)
from zonecast.estimator.rc.network import (
    ModelDefinitionError,
    ModelOptions,
    RCStructure,
    build_structure,
)
from zonecast.estimator.rc.parameters import ParameterSet
from zonecast.estimator.site import Site, load_site
from zonecast.estimator.streaming import offline_forecast_variants, offline_forecasts
from zonecast.estimator.telemetry import Telemetry, load_telemetry

__all__ = ["OPERATING_FILMS_MODE", "OPERATING_FILMS_OPTIONS", "REHEAT_LEAK", "REHEAT_LEAK_MODES",
           "Pipeline", "PipelineError", "check_reheat_leak", "identify_operating_films"]

Progress = Callable[[str], None]


class PipelineError(ValueError):
    """A pipeline step was asked for before what it needs; the message says which step."""


def _quiet(_: str) -> None:
    return None


#: how the jobs (``zonecast identify``, ``reproduce``) treat the measured reheat heat after
#: the identification: ``"none"``, as measured; ``"added"``, :meth:`Pipeline.fit_reheat_leak`
#: before the weekly profile, the air's extra heat added; ``"from_faces"``, the same with the
#: extra heat drawn from the room's faces (the reheat's total heat as measured)
REHEAT_LEAK_MODES = ("none", "added", "from_faces")
#: the default since 2026-12-06 (forty-third session), chosen on the family's training members
REHEAT_LEAK = "from_faces"

#: :meth:`Pipeline.fit_operating_films` takes the operating films when the zones' mean
#: reheat leak at the identified films reaches this many standard errors [-]
OPERATING_FILMS_MIN_T = 3.0
#: the jobs' inside films of regular operation: ``"none"`` (the identified films),
#: ``"natural"`` (:data:`~.priors.OPERATING_FILMS` whenever the algorithm is a
#: natural-convection one, ``Pipeline.identify(operating_films="natural")``) or ``"auto"``
#: (those ratios when the building's operation asks for them,
#: :meth:`Pipeline.fit_operating_films`)
OPERATING_FILMS_OPTIONS = ("none", "natural", "auto")
#: the jobs' default since 2026-12-06 (forty-fourth session; chosen on the family's 12
#: training members, docs/identification.md "Operating films chosen by the building's
#: operation")
OPERATING_FILMS_MODE = "auto"


def identify_operating_films(mode: str) -> str:
    """:meth:`Pipeline.identify`'s ``operating_films`` for a jobs' mode of
    :data:`OPERATING_FILMS_OPTIONS` (``"auto"`` identifies with the films everywhere and
    decides after, :meth:`Pipeline.fit_operating_films`); a :class:`PipelineError` for any
    other value."""
    if mode not in OPERATING_FILMS_OPTIONS:
        raise PipelineError(f"operating_films={mode!r}: use "
                            f"{' or '.join(repr(v) for v in OPERATING_FILMS_OPTIONS)}")
    return "none" if mode == "auto" else mode


def check_reheat_leak(mode: str) -> str:
    """``mode`` if it is one of :data:`REHEAT_LEAK_MODES`, else a :class:`PipelineError`."""
    if mode not in REHEAT_LEAK_MODES:
        raise PipelineError(f"reheat_leak={mode!r}: use "
                            f"{' or '.join(repr(v) for v in REHEAT_LEAK_MODES)}")
    return mode


#: weekend daytime rise of an unoccupied office's internal gains [W/m2]: ASHRAE 90.1's
#: office schedules run lights at 0.1-0.3 and equipment at 0.3 of design on weekend days
#: against 0.05 and 0.2 at night, about 2-3 W/m2 on 10 W/m2 of lighting and 10-15 of
#: equipment (docs/identification.md "Weekend daytime gains")
WEEKEND_DAY_GAIN = 2.5
#: local hours [start, end) of the weekend daytime rise
WEEKEND_DAY_HOURS = (8, 18)


#: a zone's fitted weekend daytime scale above which its weekends look occupied: the shape
#: is the rise an office shows with nobody in (:data:`WEEKEND_DAY_GAIN`); on the second family
#: (seed 1, docs/benchmarks.md "A second family nobody chose anything on") a largest zone
#: scale above 1 marked 8 of its 12 floors with weekend occupancy and none of its 7 without
OCCUPIED_WEEKEND_SCALE = 1.0


def weekend_occupancy_warning(gain_scale: Mapping | None,
                              threshold: float = OCCUPIED_WEEKEND_SCALE,
                              day_scale: Mapping | None = None,
                              metered: bool = False,
                              metered_ratio: float | None = None) -> str | None:
    """A warning when a ``daytime`` fit's scales (``result.gain_scale``: zone -> {"value",
    ...}) say people work at weekends (some zone's scale above ``threshold``), else None.
    With per-day deviations (``result.gain_day_scale``: "zone,date" -> {"value", ...}) a
    zone's largest day (s_z + d_day,z) counts. The paper identifies on unoccupied weekends; with
    people in, the weekends' unknown gains cost Table 2 and the forecasts about 0.1 K
    (docs/benchmarks.md), and weekends without people are the better data. ``metered``:
    the site has lights and plug-load meters, and the warning names the option that uses
    them.

    ``metered_ratio``: the meters' weekend daytime rise over the working days'
    (:func:`weekend_metered_ratio`). Below :data:`METERED_OCCUPIED_RATIO` the meters show
    empty weekends, so a scale above ``threshold`` is daytime heat the model lacks in
    those zones, not people (on the seed-9 family's f9-17, whose weekends are empty, zone
    S fitted 2.4 where `zonecast diagnose` finds the south windows' sun under-counted;
    docs/identification.md "Weekend daytime gains"): the warning says so and does not
    send the user to the meters' option, which would add nothing."""
    best = {z: v["value"] for z, v in (gain_scale or {}).items()}
    for key, d in (day_scale or {}).items():
        z = key.rsplit(",", 1)[0]
        if z in best:
            best[z] = max(best[z], (gain_scale or {})[z]["value"] + d["value"])
    high = {z: v for z, v in best.items() if v > threshold}
    if not high:
        return None
    zones = ", ".join(f"{z} {s:.1f}" for z, s in high.items())
    if metered_ratio is not None and metered_ratio < METERED_OCCUPIED_RATIO:
        return (f"zones {zones} fitted a weekend daytime rise of more than {threshold:g} x an "
                f"empty office's ({WEEKEND_DAY_GAIN} W/m2), but the site's meters show empty "
                f"weekends (their weekend daytime rise is {metered_ratio:.2f} of the working "
                f"days', below {METERED_OCCUPIED_RATIO:g}): the rise stands for daytime heat "
                "the model lacks in those zones, not for people, and the validation weekend "
                "and the forecasts pay for it where that heat differs (another season's sun); "
                "`zonecast diagnose` ranks which unmodelled effect it is "
                "(docs/identification.md \"Weekend daytime gains\")")
    return (f"the weekends look occupied: zones {zones} fitted a weekend daytime rise of more "
            f"than {threshold:g} x an empty office's ({WEEKEND_DAY_GAIN} W/m2). The "
            "identification assumes weekends without people (paper section 2-B); with people in, "
            "expect Table 2 and the 24-h forecasts about 0.1 K worse, and excite on weekends "
            "when nobody works if you can (docs/identification.md)"
            + ("; the site has lights and plug-load meters: --weekend-gains metered takes "
               "their weekend rise as known gains (docs/identification.md \"Metered weekend "
               "gains\")" if metered else ""))


def weekend_daytime_shape(data: ModelData) -> np.ndarray:
    """(N, n_zones) [W/m2]: :data:`WEEKEND_DAY_GAIN` on Saturday and Sunday rows whose local
    hour is in :data:`WEEKEND_DAY_HOURS`, else 0 (a shape for ``identify(gain_shape=...)``)."""
    local = data.local_times()
    on = ((local.day_of_week >= 5) & (local.hour >= WEEKEND_DAY_HOURS[0])
          & (local.hour < WEEKEND_DAY_HOURS[1]))
    return np.repeat(np.where(np.asarray(on), WEEKEND_DAY_GAIN, 0.0)[:, None],
                     len(data.zones), axis=1)


#: prior (mean, sd) [-] of the daytime shape's scale when the meters give the weekends'
#: lights and plug loads: the shape stands for those (WEEKEND_DAY_GAIN), so with them known
#: its scale carries only what no meter sees (people, the model's own daytime error)
METERED_SHAPE_PRIOR = (0.0, 1.0)
#: local hours [start, end) of the weekend nights whose median metered power is a zone's
#: base load (night lighting, standby plug loads), which c_IG carries
METERED_BASE_HOURS = (0, 6)


#: ``constant_gains="meters"``: the sd of each metered zone's c_IG prior is the meters' own
#: uncertainty, this fraction of the base [-] (the testbed's meters: 0.5 % noise), but at
#: least :data:`METERED_BASE_SD_MIN` [W/m2] (a meter's 1 W resolution on a floor of a few
#: hundred m2, and the median of a few nights)
METERED_BASE_SD_REL = 0.005
METERED_BASE_SD_MIN = 0.05
CONSTANT_GAINS = ("fitted", "meters")


def check_constant_gains(mode: str) -> str:
    """``mode`` if it is one of :data:`CONSTANT_GAINS`, else a :class:`PipelineError` saying
    which are."""
    if mode not in CONSTANT_GAINS:
        raise PipelineError(f"constant_gains={mode!r}: use "
                            f"{' or '.join(repr(v) for v in CONSTANT_GAINS)}")
    return mode


def metered_base_gains(data: ModelData, zone_area) -> np.ndarray:
    """(n_zones,) [W/m2]: each zone's metered base load, the median of its weekend
    readings between :data:`METERED_BASE_HOURS` local time (``data.power``, lights and plug
    loads) per m2 of the zone's floor (``zone_area`` [m2], zones in ``data.zones`` order);
    NaN for a zone without a meter or without such a reading. Electricity used in a room
    is heat in it, so on an empty weekend night this is the zone's whole internal gain:
    the paper's constant c_IG, known (:meth:`Pipeline.identify`'s ``constant_gains``)."""
    area = np.asarray(zone_area, float)
    base = _metered_base(data)
    return np.where(area > 0, base / np.where(area > 0, area, 1.0), np.nan)


def _metered_base(data: ModelData) -> np.ndarray:
    """(n_zones,) [W]: the median of each zone's weekend readings between
    :data:`METERED_BASE_HOURS` local time; NaN without a meter or such a reading."""
    out = np.full(len(data.zones), np.nan)
    if data.power is None:
        return out
    local = data.local_times()
    night = (np.asarray(local.day_of_week >= 5)
             & np.asarray((local.hour >= METERED_BASE_HOURS[0])
                          & (local.hour < METERED_BASE_HOURS[1])))
    for j in range(len(data.zones)):
        p = data.power[:, j]
        base = p[night & np.isfinite(p)]
        if len(base):
            out[j] = np.median(base)
    return out


#: the building's weekend daytime rise of metered lights and plug loads, as a fraction of the
#: working days' (:func:`weekend_metered_ratio`), from which ``weekend_gains="auto"`` takes the
#: meters' rise as known weekend gains: chosen on the seed-0 family's training members, whose
#: floors without weekend people show 0.09-0.10 (cleaning, short visits) and those with them
#: 0.19-0.37 (docs/identification.md "Metered gains where the weekends are occupied")
METERED_OCCUPIED_RATIO = 0.15


def weekend_metered_ratio(data: ModelData) -> float | None:
    """The building's metered daytime rise on weekends over that of working days [-]: the
    mean of the zones' summed meters (``data.power``) between :data:`WEEKEND_DAY_HOURS` local
    time less the median between :data:`METERED_BASE_HOURS`, Saturdays and Sundays against
    Monday to Friday, over the rows where every zone's power is known. None without meters
    or without a working-day rise to compare with. About the share of a working day's
    people that come in at weekends, plus the cleaning and short visits of an empty floor."""
    if data.power is None:
        return None
    p = np.asarray(data.power, float)
    ok = np.all(np.isfinite(p), axis=1)
    total = p.sum(axis=1)
    local = data.local_times()
    weekend = np.asarray(local.day_of_week >= 5)
    hour = np.asarray(local.hour)
    day = (hour >= WEEKEND_DAY_HOURS[0]) & (hour < WEEKEND_DAY_HOURS[1])
    night = (hour >= METERED_BASE_HOURS[0]) & (hour < METERED_BASE_HOURS[1])

    def rise(days: np.ndarray) -> float | None:
        on, base = ok & days & day, ok & days & night
        if not on.any() or not base.any():
            return None
        return float(total[on].mean() - np.median(total[base]))

    working, weekends = rise(~weekend), rise(weekend)
    if working is None or weekends is None or not working > 0:
        return None
    return weekends / working


def weekend_metered_gains(data: ModelData, zone_area, *, every_day: bool = False
                          ) -> np.ndarray:
    """(N, n_zones) [W/m2]: on Saturday and Sunday rows, each zone's metered electric power
    of lights and plug loads (``data.power``) above its base load, per m2 of the zone's
    floor (``zone_area`` [m2], zones in ``data.zones`` order); 0 on working days (with
    ``every_day`` the same on them too: the x(0) filter's ``x0_meters``), for zones
    without a meter and on rows where a zone's meters left it unknown (a gap longer than
    :meth:`~.telemetry.Telemetry.power` fills). The base load is the
    median of the zone's weekend readings between :data:`METERED_BASE_HOURS` local time
    (the constant part of the gains is c_IG's). Electricity used in a room becomes heat in
    it, so this part of the weekends' gains is known, day by day."""
    out = np.zeros((len(data.times), len(data.zones)))
    if data.power is None:
        return out
    weekend = np.asarray(data.local_times().day_of_week >= 5)
    area = np.asarray(zone_area, float)
    base = _metered_base(data)
    rows = np.ones(len(data.times), bool) if every_day else weekend
    for j in range(len(data.zones)):
        if not np.isfinite(base[j]) or not area[j] > 0:
            continue
        p = data.power[:, j]
        ok = rows & np.isfinite(p)
        out[ok, j] = np.maximum(p[ok] - base[j], 0.0) / area[j]
    return out


class Pipeline:
    """One building's way from its description to forecasts.

    Parameters
    ----------
    site : Site
        The site description (:func:`~zonecast.estimator.site.load_site`).
    site_path : path, optional
        The file ``site`` was read from (model files refer to it).
    options : ModelOptions, optional
        Modelling choices (default :class:`ModelOptions`).
    energyplus_dir : path, optional
        EnergyPlus used to read the building's IDF (default as
        :func:`~zonecast.estimator.idf.find_energyplus`).
    """

    def __init__(self, site: Site, *, site_path: str | os.PathLike | None = None,
                 options: ModelOptions | None = None,
                 energyplus_dir: str | os.PathLike | None = None):
        self.site = site
        self.site_path = None if site_path is None else Path(site_path)
        self.options = options or ModelOptions()
        self.energyplus_dir = energyplus_dir
        self._building: Building | None = None
        self._structure: RCStructure | None = None
        self._room_volume: dict[str, float] | None = None
        #: parameters of the last :meth:`identify` (or of the model file)
        self.params: ParameterSet | None = None
        #: the last :meth:`identify` result
        self.identification: IdentificationResult | None = None
        #: the last :meth:`weekly_profile` (or the model file's)
        self.profile: WeeklyProfile | None = None
        #: start dates of the weeks the profile was estimated from
        self.profile_weeks: list[str] = []
        #: filter noise of the streaming estimator (the model file's, else defaults)
        self.noise = NoiseSettings()
        #: internal gains [W/m2] per row the last :meth:`identify`'s x(0) filter knew
        #: (``x0_profile_days``), else None
        self.x0_gains: np.ndarray | None = None
        #: per box, the factor on its measured reheat heat in every use after the
        #: identification (:meth:`fit_reheat_leak`; None: 1, the heat as measured)
        self.reheat_scale: np.ndarray | None = None
        #: the last :meth:`fit_reheat_leak`
        self.reheat_leak: ReheatLeak | None = None
        #: the air's extra reheat heat is drawn from the room's faces (BilinearModel)
        self.reheat_from_faces = False
        #: the last fit_reheat_leak's tracked gains (data, key, (rows, f_IG)), so that a
        #: fit at the same parameters and weeks does not track them again
        self._leak_tracks: tuple | None = None
        self._bundle: ModelBundle | None = None

    # --- construction ------------------------------------------------------------------
    @classmethod
    def from_site(cls, site: Site | str | os.PathLike, *, options: ModelOptions | None = None,
                  energyplus_dir: str | os.PathLike | None = None) -> Pipeline:
        """A pipeline for a site description (a :class:`Site` or the path of its YAML)."""
        if isinstance(site, Site):
            return cls(site, options=options, energyplus_dir=energyplus_dir)
        return cls(load_site(site), site_path=site, options=options,
                   energyplus_dir=energyplus_dir)

    @classmethod
    def from_model_file(cls, path: str | os.PathLike) -> Pipeline:
        """A pipeline holding an identified model (:func:`~.artifact.load_model_file`):
        its site, structure, parameters, profile and noise."""
        bundle = load_model_file(path)
        pipe = cls(bundle.site, site_path=bundle.site_path,
                   options=bundle.model.structure.options)
        pipe._structure = bundle.model.structure
        pipe._room_volume = dict(bundle.room_volume)
        pipe.params = bundle.model.params
        pipe.profile = bundle.profile
        pipe.noise = bundle.noise
        if not np.all(bundle.model.reheat_scale == 1.0):
            pipe.reheat_scale = bundle.model.reheat_scale.copy()
            pipe.reheat_from_faces = bundle.model.reheat_from_faces
        pipe._bundle = bundle
        return pipe

    def with_options(self, options: ModelOptions) -> Pipeline:
        """A pipeline for the same site with other modelling choices (shares the building
        already read, so EnergyPlus is not run again)."""
        other = Pipeline(self.site, site_path=self.site_path, options=options,
                         energyplus_dir=self.energyplus_dir)
        other._building = self._building
        return other

    # --- model -------------------------------------------------------------------------
    def building(self) -> Building:
        """The building read from the site's EnergyPlus file (needs EnergyPlus; cached)."""
        if self._building is None:
            self._building = read_building(self.site.idf_path, self.energyplus_dir,
                                           weather_file=self.site.weather_path)
        return self._building

    def _building_or_none(self) -> Building | None:
        """The building if it can be read (a pipeline from a model file may have no
        EnergyPlus)."""
        if self._building is None and self._bundle is not None:
            return None
        return self.building()

    def structure(self) -> RCStructure:
        """The parameter-free RC structure (paper section 3; cached)."""
        if self._structure is None:
            if self.options.sky == "cloud" and self.site.points.cloud_cover is None:
                raise ModelDefinitionError(
                    "sky='cloud' takes the sky's temperature from the site's cloud cover, "
                    "and the site maps no points.cloud_cover: add the point (a weather "
                    "station's or weather service's opaque cloud cover) or choose sky "
                    "'clear' or 'none'")
            building = self.building()
            self._structure = build_structure(
                building, self.site.zones, {b: box.room for b, box in self.site.boxes.items()},
                self.options)
            self._room_volume = {name: z.volume for name, z in building.zones.items()}
        return self._structure

    @property
    def room_volume(self) -> dict[str, float]:
        """Room -> air volume [m3]."""
        self.structure()
        assert self._room_volume is not None
        return self._room_volume

    def model(self, params: ParameterSet | Mapping[str, float] | Sequence[float] | None = None
              ) -> BilinearModel:
        """The bilinear model with ``params`` (default: the identified ones if any, else
        the physical starting values)."""
        structure = self.structure()
        if params is None:
            params = self.params
        if params is not None and not isinstance(params, ParameterSet):
            params = ParameterSet(list(structure.zones), params, structure.extra_params)
        return BilinearModel(structure, params, reheat_scale=self.reheat_scale,
                             reheat_from_faces=self.reheat_from_faces)

    # --- data --------------------------------------------------------------------------
    def telemetry(self, path: str | os.PathLike) -> Telemetry:
        """Validated telemetry: a file, or a folder holding ``telemetry.csv``."""
        path = Path(path)
        return load_telemetry(path / "telemetry.csv" if path.is_dir() else path, self.site)

    def data(self, telemetry: Telemetry | str | os.PathLike) -> ModelData:
        """Telemetry in the model's terms (paper u, v, y; sensors weighted like C)."""
        tel = telemetry if isinstance(telemetry, Telemetry) else self.telemetry(telemetry)
        model = self.model()
        return model_data(tel, model.room_weights(),
                          facade_azimuths=model.structure.facade_azimuths,
                          scheduled=model.structure.scheduled,
                          shading=model.structure.facade_shading,
                          panes=model.structure.window_panes)

    # --- identification ----------------------------------------------------------------
    def identify(self, data: ModelData, train: Sequence[str] | None = None,
                 validation: Sequence[str] | None = None, *, n_starts: int = 1, seed: int = 0,
                 progress: Progress = _quiet, priors: bool | Mapping[str, Prior] = True,
                 sigma_e: float = 0.3, window: str = "weekend",
                 weekend_gains: bool | str = "auto",
                 gains_weeks: Sequence[int] | None = None,
                 agree_rtol: float = 1e-3, films: str | None = None,
                 x0_profile_days: int | None = None,
                 x0_offset_sd: float | None = None,
                 day_scale_sd: float | None = None,
                 positive_priors: str = "log",
                 operating_films: str = "none",
                 x0_meters: bool | str = "auto",
                 constant_gains: str = "fitted") -> IdentificationResult:
        """Identify the 13 parameters (paper section 4-A) from excitation weekends.

        Defaults follow the paper's split of the site's excitation weekends (its
        ``experiments``): training on the second and third, validation on the first.
        ``priors``: True (the default since 2026-11-24, chosen on the family's training
        members with the IDF's infiltration, docs/identification.md) for a MAP fit with
        :func:`~.priors.building_priors` of this building (window U and SHGC from its IDF),
        a mapping of priors, or False for the paper's least squares; ``sigma_e`` [K]
        the MAP residual scale. ``window``: fit whole weekends (the paper) or the site's
        declared ``experiments`` with a lead-in (:func:`~.identify.identification_spans`).

        ``films``: the inside films' priors and starting values: ``"combined"`` (the
        handbook's convection + radiation films), ``"convective"``
        (:data:`~.priors.CONVECTIVE_FILMS`, convection alone, EnergyPlus's ``Simple``
        constants) or ``"idf"`` (convection alone, of the IDF's declared inside algorithm:
        :func:`~.priors.convective_films`, Walton's natural convection for TARP, EnergyPlus's
        default); default ``"convective"`` for a structure with interior long-wave exchange,
        else ``"combined"``.

        ``positive_priors``: ``"log"`` (the default since 2026-12-06, chosen on the
        family's training members, docs/identification.md "Log-normal priors of the films
        and the glazing U"): the films' and U_win's priors are log-normal (same median and
        relative spread), so a film cannot fall to its bound at the cost of two standard
        deviations; ``"normal"``: Gaussian as before (:func:`~.priors.building_priors`).

        ``agree_rtol``: the starts stop once two reach the same cost within it
        (:func:`~.identify.identify`; 0 runs all ``n_starts``).

        ``operating_films``: ``"none"`` (the default): the identified films everywhere.
        ``"natural"`` (measured 2026-12-06 and not the default, docs/identification.md
        "Operating films"): when the IDF declares a natural-convection inside algorithm
        (TARP, EnergyPlus's default), the inside films of regular operation are the
        identified ones times :data:`~.priors.OPERATING_FILMS`, the ratios EnergyPlus shows
        on the family's VAV floors between their experiments and working hours:
        :attr:`params` (gains, forecasts, the model file) carry them, the result's
        :attr:`~.identify.IdentificationResult.model` keeps the identified films (Table 2).
        The ratios are not general: the DOE small office's packaged units give the reverse
        on its walls.

        ``weekend_gains`` (default ``"auto"`` since 2026-12-04: ``"metered"`` when the
        site's meters say its weekends are occupied (:func:`weekend_metered_ratio` at least
        :data:`METERED_OCCUPIED_RATIO`), else ``"daytime"`` (the default from 2026-11-25);
        both chosen on the family's training members: docs/identification.md "Weekend
        daytime gains", "Metered gains where the weekends are occupied"; ``"none"`` or
        False: the paper's fit): a building occupied at weekends has internal gains on the
        identification weekends that the paper's fit (f_IG = 0) leaves to the parameters.
        With it the fit runs twice: the paper's, then the weekly internal-gains profile of
        the whole weeks ``gains_weeks`` (indices into :func:`~.forecast.whole_weeks`;
        default all) that hold no experiment row, with those parameters, then the fit
        again from them (one start) with the profile as known f_IG on every row
        (docs/identification.md). ``"scaled"``: the same, but the profile is a per-zone
        shape whose scale is fitted with the parameters (:func:`~.identify.identify`
        ``gain_shape``), so a weekend without people can say so; True or ``"known"``:
        the profile as it is. ``"daytime"``: one fit in which each zone's weekend gains
        rise by s_z x :data:`WEEKEND_DAY_GAIN` between 08 and 18 h local time on Saturdays
        and Sundays (:func:`weekend_daytime_shape`), s_z fitted with the parameters (prior
        1 +- 1, bounds 0-5): the weekend daytime lighting and equipment of an
        "unoccupied" office, whatever the weekday profile says. ``"metered"``: the same
        fit with, in addition, each zone's metered electric power of lights and plug loads
        above its weekend night base as known gains on the weekends
        (:func:`weekend_metered_gains`; the site's ``points.power``): electricity used in
        a room is heat in it, day by day, where the daytime shape can only guess.

        ``x0_profile_days`` (an option, default off; docs/identification.md "The slow
        states' x(0)"): after the fit, the weekly internal-gains profile of the whole
        weeks ``gains_weeks`` without experiments (as for ``"known"``), then the fit again
        from its parameters (one start) with the x(0) filter running that many days
        before each weekend and knowing the profile's gains there (the simulated
        weekends keep the mode's own gains); :attr:`x0_gains` keeps them for
        :func:`~.identify.weekend_simulations`.

        ``x0_meters``: the x(0) filter before each weekend knows each zone's metered
        lights and plug loads above their base on the working days
        (:func:`weekend_metered_gains` with ``every_day``): the working day before a
        weekend heats the rooms' faces, which a filter with f_IG = 0 leaves about a kelvin
        too cold (docs/identification.md "The x(0) filter told the meters"). ``"auto"``
        (the default since 2026-12-07, chosen on the family's training members): on where
        the site maps meters (``points.power``) and ``x0_profile_days`` is not given;
        True: on (needs the meters; not with ``x0_profile_days``); False: off. Kept in
        :attr:`x0_gains` as ``x0_profile_days``'s profile is.

        ``constant_gains``: ``"fitted"`` (the default, the paper's c_IG with the
        handbook's weak prior) or ``"meters"`` (an option): each metered zone's c_IG is its
        metered weekend night base (:func:`metered_base_gains`), its prior's sd the meters'
        uncertainty (:data:`METERED_BASE_SD_REL`, at least :data:`METERED_BASE_SD_MIN`), so
        it is known rather than fitted and the fit cannot lower it to pay for heat the
        structure puts elsewhere (docs/identification.md "The constant gains from the
        meters"); needs the meters and ``priors`` True.

        ``day_scale_sd`` (an option, default off; with ``"daytime"``): each training
        weekend day also fits its own deviation of every zone's daytime scale, prior 0 ±
        this value (:func:`~.identify.identify`): a building whose people come in on some
        weekend days and not others.

        ``x0_offset_sd`` [K] (an option, default off): every fit also estimates one offset
        per zone of the slow states' x(0), shared by the weekends, with a prior 0 ± this sd
        (:func:`~.identify.identify`); Table 2 and Fig. 1 start every weekend, the
        validation one included, at x_KF(0) plus the offsets; the forecasts do not use
        this filter.
        """
        modes = {False: None, "none": None, True: "known", "known": "known",
                 "scaled": "scaled", "daytime": "daytime", "metered": "metered",
                 "auto": "auto"}
        if weekend_gains not in modes:
            raise PipelineError(f"weekend_gains={weekend_gains!r}: use 'auto', 'none', "
                                "'known', 'scaled', 'daytime' or 'metered'")
        weekend_gains = modes[weekend_gains]
        ratio = weekend_metered_ratio(data)
        if weekend_gains == "auto":
            weekend_gains = ("metered" if ratio is not None and ratio >= METERED_OCCUPIED_RATIO
                             else "daytime")
        if weekend_gains == "metered":
            self._need_meters(data)
        if check_constant_gains(constant_gains) == "meters":
            if priors is not True:
                raise PipelineError("constant_gains='meters' sets c_IG's priors from the "
                                    "meters: keep priors=True (the building's priors)")
            if data.power is None:
                raise PipelineError("constant_gains='meters' needs electricity meters: map "
                                    "each zone's lights and plug-load meters under "
                                    "points.power in the site description (docs/data.md)")
        if films is None:
            films = "convective" if self.options.interior_radiation == "star" else "combined"
        if films not in ("combined", "convective", "idf"):
            raise PipelineError(f"films={films!r}: use 'combined', 'convective' or 'idf'")
        if positive_priors not in POSITIVE_PRIORS:
            raise PipelineError(f"positive_priors={positive_priors!r}: use "
                                f"{' or '.join(repr(v) for v in POSITIVE_PRIORS)}")
        if operating_films not in OPERATING_FILM_MODES:
            raise PipelineError(f"operating_films={operating_films!r}: use "
                                f"{' or '.join(repr(v) for v in OPERATING_FILM_MODES)}")
        sats = [str(s.date()) for s in excitation_saturdays(data)]
        train = list(train) if train else sats[1:3]
        validation = list(validation) if validation is not None else sats[:1]
        if not train:
            raise PipelineError("no excitation weekend found: give the training Saturdays "
                                "(the site's experiments list marks excitation periods)")
        start = ParameterSet(list(self.site.zones), extra=self.structure().extra_params)
        convective = films in ("convective", "idf")
        table = (convective_films(self._building_or_none()) if films == "idf"
                 else CONVECTIVE_FILMS)
        if convective:  # films as convection alone: start where their priors are
            start = start.copy({k: v[0] for k, v in table.items()})
        own_roof = "gamma_roof" in start.param_names
        if own_roof:  # the roofs' own film starts at its prior's mean (the climate's film)
            start = start.copy({"gamma_roof": roof_film_prior(self._building_or_none())[0]})
        metered_cig: dict[str, float] = {}
        if constant_gains == "meters":
            base = metered_base_gains(data, self.zone_floor_areas())
            metered_cig = {f"c_IG[{z}]": float(b) for z, b in zip(data.zones, base)
                           if np.isfinite(b)}
            start = start.copy(metered_cig)  # start where they are known
        if priors is True:
            priors = building_priors(start, self._building_or_none(),
                                     convective="idf" if films == "idf" else convective,
                                     positive=positive_priors)
            for name, b in metered_cig.items():
                priors[name] = Prior(b, max(METERED_BASE_SD_REL * b, METERED_BASE_SD_MIN),
                                     "metered weekend night base of the zone's lights and "
                                     "plug loads")
        # the identification sees the reheat as measured (fit_reheat_leak comes after it)
        self.reheat_scale, self.reheat_leak, self.reheat_from_faces = None, None, False
        metered_x0 = None
        if x0_meters not in (True, False, "auto"):
            raise PipelineError(f"x0_meters={x0_meters!r}: use True, False or 'auto'")
        if x0_meters == "auto":
            x0_meters = data.power is not None and x0_profile_days is None
        if x0_meters:
            if x0_profile_days is not None:
                raise PipelineError("x0_meters and x0_profile_days both tell the x(0) filter "
                                    "the working days' gains; choose one")
            self._need_meters(data)
            metered_x0 = weekend_metered_gains(data, self.zone_floor_areas(), every_day=True)
            # the working days' only: the weekends' gains are the weekend mode's
            metered_x0[np.asarray(data.local_times().day_of_week >= 5)] = 0.0
        res = identify(self.model(start), data, train, validation, n_starts=n_starts,
                       seed=seed, progress=progress, priors=priors or None, sigma_e=sigma_e,
                       window=window, agree_rtol=agree_rtol, x0_offset_sd=x0_offset_sd,
                       day_scale_sd=(day_scale_sd if weekend_gains in ("daytime", "metered")
                                     else None),
                       start=(start.values if convective or own_roof or metered_cig
                              else None),
                       f_ig=self.weekend_known_gains(data, weekend_gains),
                       gain_shape=self.weekend_shape(data, weekend_gains),
                       shape_prior=self._shape_prior(weekend_gains), x0_gains=metered_x0)
        if weekend_gains in ("known", "scaled"):
            self.params = res.model.params
            progress("weekly internal-gains profile for the weekends' gains")
            f_ig = self._quiet_weeks_gains(data, gains_weeks)
            if f_ig is not None:
                known, shape = (f_ig, None) if weekend_gains == "known" else (None, f_ig)
                res = identify(self.model(res.model.params), data, train, validation,
                               seed=seed, progress=progress, priors=priors or None,
                               sigma_e=sigma_e, window=window, f_ig=known, gain_shape=shape,
                               start=res.model.params.values, x0_offset_sd=x0_offset_sd,
                               x0_gains=metered_x0)
        self.x0_gains = metered_x0
        if x0_profile_days is not None:
            if x0_profile_days < 1:
                raise PipelineError(f"x0_profile_days={x0_profile_days}: give 1 or more days")
            self.params = res.model.params
            progress("weekly internal-gains profile for the x(0) filter")
            x0_gains = self._quiet_weeks_gains(data, gains_weeks)
            if x0_gains is None:
                raise PipelineError("x0_profile_days needs whole weeks without an experiment "
                                    "for the internal-gains profile")
            per_day = int(pd.Timedelta("1D") / (data.times[1] - data.times[0]))
            res = identify(self.model(res.model.params), data, train, validation,
                           seed=seed, progress=progress, priors=priors or None,
                           sigma_e=sigma_e, window=window, start=res.model.params.values,
                           f_ig=self.weekend_known_gains(data, weekend_gains),
                           gain_shape=self.weekend_shape(data, weekend_gains),
                           shape_prior=self._shape_prior(weekend_gains), x0_gains=x0_gains,
                           x0_window=x0_profile_days * per_day,
                           x0_offset_sd=x0_offset_sd,
                           day_scale_sd=(day_scale_sd if weekend_gains in ("daytime", "metered")
                                     else None))
            self.x0_gains = x0_gains
        res.weekend_gains = weekend_gains or "none"
        res.weekend_metered_ratio = ratio
        res.x0_gains_source = ("profile" if x0_profile_days is not None
                               else "meters" if metered_x0 is not None else None)
        self.identification = res
        self.params = res.model.params
        factors = operating_film_ratios(self._building_or_none(), operating_films)
        if factors:
            res.operating_films = factors
            self.params = res.model.params.copy(
                {k: res.model.params[k] * f for k, f in factors.items()})
        self._bundle = None
        return res

    @staticmethod
    def _shape_prior(mode: str | None) -> tuple[float, float]:
        """Prior of the daytime shape's scale: :data:`METERED_SHAPE_PRIOR` with the meters'
        rise known, else identify's 1 ± 1 (the shape is the expected lights and plugs)."""
        return METERED_SHAPE_PRIOR if mode == "metered" else (1.0, 1.0)

    def zone_floor_areas(self) -> np.ndarray:
        """Floor area [m2] of each model zone (its rooms' floors), site zone order: the
        a_floor of the paper's internal gains (eq:q_ig)."""
        rooms = {k.upper(): v for k, v in self.building().zones.items()}
        return np.array([sum(rooms[r.upper()].floor_area for r in members)
                         for members in self.site.zones.values()])

    def weekend_shape(self, data: ModelData, mode: str | None) -> np.ndarray | None:
        """The weekend gains shape [W/m2] (N, n_zones) a ``weekend_gains`` mode fits a
        per-zone scale of: :func:`weekend_daytime_shape` for ``"daytime"`` and
        ``"metered"``; None for the other modes."""
        return weekend_daytime_shape(data) if mode in ("daytime", "metered") else None

    def weekend_known_gains(self, data: ModelData, mode: str | None) -> np.ndarray | None:
        """The weekends' known gains [W/m2] (N, n_zones) of a ``weekend_gains`` mode: the
        metered rise (:func:`weekend_metered_gains`) for ``"metered"``, else None."""
        if mode != "metered":
            return None
        self._need_meters(data)
        return weekend_metered_gains(data, self.zone_floor_areas())

    @staticmethod
    def _need_meters(data: ModelData) -> None:
        if data.power is None:
            raise PipelineError("weekend_gains='metered' needs electricity meters: map each "
                                "zone's lights and plug-load meters under points.power in the "
                                "site description (docs/data.md)")

    def _quiet_weeks_gains(self, data: ModelData, gains_weeks: Sequence[int] | None
                           ) -> np.ndarray | None:
        """The weekly internal-gains profile [W/m2] at every row of ``data``, estimated with
        the current parameters from the whole weeks ``gains_weeks`` (default all) that hold
        no experiment row (never the identification weekends: their excitation misfit
        would come back as gains); None without such a week."""
        weeks = whole_weeks(data)
        pick = range(len(weeks)) if gains_weeks is None else gains_weeks
        quiet = [i for i in pick if not data.excitation[slice(*weeks[i]["rows"])].any()]
        if not quiet:
            return None
        return np.nan_to_num(self.weekly_profile(data, weeks=quiet)(data.times))

    def fit_operating_films(self, data: ModelData, *, progress: Progress = _quiet,
                            weeks: Sequence[int] | None = None,
                            min_t: float = OPERATING_FILMS_MIN_T) -> dict[str, float]:
        """The inside films of regular operation, chosen by the building's own operation.

        A natural-convection film (TARP, EnergyPlus's default) grows with the face-to-air
        temperature difference, which the experiments' widened thermostat and forced
        airflows make larger than regular operation does; an air whose films are too
        strong hands the boxes' reheat to the faces too fast, and its gains estimate then
        carries part of the reheat (docs/identification.md "Operating films"). So: the
        reheat leak k of every zone at the identified films
        (:meth:`fit_reheat_leak`, measured and not kept); when the zones' precision-weighted
        mean k exceeds ``min_t`` standard errors, the pipeline's parameters take the films
        of :data:`~.priors.OPERATING_FILMS` (:func:`~.priors.operating_film_ratios`),
        else the identified films stay. Call it after :meth:`identify`; a building
        without a natural-convection algorithm or without measured reheat keeps its
        films. Returns the factors applied ({} when none); the identification result
        records them and the test (``operating_films``, ``operating_films_test``)."""
        if self.identification is None:
            raise PipelineError("fit_operating_films needs an identified model: call "
                                "identify() first")
        factors = operating_film_ratios(self._building_or_none(), "natural")
        res = self.identification
        res.operating_films, res.operating_films_test = None, None
        self.params = res.model.params
        self._bundle = None
        if not factors or not np.any(data.reheat):
            return {}
        leak = self.fit_reheat_leak(data, weeks=weeks, progress=progress)
        self.reheat_scale, self.reheat_leak, self.reheat_from_faces = None, None, False
        self._bundle = None
        if leak is None:
            return {}
        w = np.where(np.isfinite(leak.stderr) & (leak.stderr > 0),
                     1.0 / np.maximum(leak.stderr, 1e-300) ** 2, 0.0)
        if w.sum() <= 0:
            return {}
        k_mean = float(w @ leak.fitted / w.sum())
        se = float(1.0 / np.sqrt(w.sum()))
        applied = k_mean > min_t * se
        res.operating_films_test = {"k_mean": k_mean, "stderr": se, "min_t": min_t,
                                    "applied": bool(applied)}
        if not applied:
            return {}
        res.operating_films = dict(factors)
        self.params = res.model.params.copy(
            {k: res.model.params[k] * f for k, f in factors.items()})
        return dict(factors)

    def fit_reheat_leak(self, data: ModelData, *, progress: Progress = _quiet,
                        weeks: Sequence[int] | None = None,
                        from_faces: bool = False) -> ReheatLeak | None:
        """Scale each zone's measured reheat heat by 1 + k, k the share of it that the
        per-step gains estimate of regular operation carries
        (:func:`~zonecast.estimator.gains.fit_reheat_leak`: the gains of every whole week
        of ``data``, or of the weeks of index ``weeks``, their excitation rows left out,
        tracked with the identified parameters and the heat as measured; the
        weekly profile and the reheat term fitted together on the local time-of-week axis).
        Sets :attr:`reheat_scale` for every later use (gains, profile, forecasts, model
        file); Table 2 keeps the identification's model. ``from_faces``: the air's extra
        heat k c_p u r is drawn from the room's inside faces by their film conductances
        (the reheat's total heat stays the measured one), else it is added. None (nothing
        changed) without such a week or without measured reheat."""
        self.reheat_scale, self.reheat_leak = None, None
        self.reheat_from_faces = False
        if not np.any(data.reheat):
            return None
        every = whole_weeks(data)
        pick = every if weeks is None else [every[i] for i in weeks]
        if not pick:
            return None
        model = self.model()
        st = model.structure
        area = zone_floor_area(model)
        box_zone = st.state_zones()[np.asarray(st.room_of_box)]
        site_box = np.array([b in self.site.boxes for b in st.boxes])
        key = (self.params.values.tobytes(), None if weeks is None else tuple(weeks))
        kept = self._leak_tracks
        if kept is not None and kept[0] is data and kept[1] == key:
            r, f = kept[2]  # the same weeks with the same model (fit_operating_films kept them)
        else:
            rows, fs = [], []
            for i, w in enumerate(pick):
                progress(f"reheat leak: week {i + 1}/{len(pick)}")
                t = track_week(model, data, w["rows"])
                rows.append(t.rows)
                fs.append(t.track.f_ig)
            r = np.concatenate(rows)
            f = np.concatenate(fs)
            f[data.excitation[r]] = np.nan  # the experiments' forced boxes
            self._leak_tracks = (data, key, (r, f))
        q_box = model.reheat_heat(data.u[r], data.reheat[r])  # [W] per box
        q = np.column_stack([q_box[:, site_box & (box_zone == j)].sum(axis=1)
                             for j in range(model.n_zones)]) / area
        leak = fit_reheat_leak(data.times[r], f, q, data.timezone,
                               step=data.times[1] - data.times[0])
        self.reheat_leak = leak
        scale = np.ones(len(st.boxes))
        scale[site_box] = 1.0 + leak.k[box_zone[site_box]]
        self.reheat_scale = scale
        self.reheat_from_faces = bool(from_faces)
        self._bundle = None
        return leak

    def weekly_profile(self, data: ModelData, *, progress: Progress = _quiet,
                       weeks: Sequence[int] | None = None) -> WeeklyProfile | None:
        """The fixed weekly internal-gains profile (paper Eq:fixed_ig) from every whole
        week of ``data`` (or the whole weeks of index ``weeks``) with the current
        parameters; None without a whole week."""
        every = whole_weeks(data)
        weeks = every if weeks is None else [every[i] for i in weeks]
        if not weeks:
            return None
        fitted = self.model()
        tracks = []
        for i, w in enumerate(weeks):
            progress(f"week {i + 1}/{len(weeks)}")
            tracks.append(track_week(fitted, data, w["rows"]))
        # an empty day (Monday, each week's warm-up) is filled from its own day class
        mode = forecast_module.PROFILE_FILL
        if mode not in ("operating", "day", "all"):
            raise PipelineError(f"forecast.PROFILE_FILL {mode!r}: use 'operating', 'day' or "
                                "'all'")
        th = self.site.thermostat
        classes = None if mode == "all" else DayCalendar.for_site(self.site).working_days
        start = th.occupied_hours[0] if mode == "operating" and th is not None else 0.0
        self.profile = fixed_profile(data, tracks, classes, start)
        self.profile_weeks = [w["start"] for w in weeks]
        self._bundle = None
        return self.profile

    # --- artefact ----------------------------------------------------------------------
    def write_model_file(self, path: str | os.PathLike, *,
                         weekly_profile: dict | None = None,
                         extra: dict | None = None) -> Path:
        """Write the model file and its structure (:mod:`~zonecast.estimator.artifact`).

        ``weekly_profile`` overrides the pipeline's profile ({"zones", "values"}); the
        identification result and the profile's weeks go in as informational keys.
        """
        if self.site_path is None:
            raise PipelineError("the pipeline was made from a Site object: make it with "
                                "Pipeline.from_site(path) so the model file can refer to it")
        site_file = self.site_path
        if site_file.is_dir():
            raise PipelineError(f"{site_file} is a folder; the pipeline needs the site file")
        structure = self.structure()
        if weekly_profile is None and self.profile is not None:
            weekly_profile = {"zones": list(self.site.zones),
                              "values": self.profile.values.tolist(),
                              "counts": np.asarray(self.profile.counts).astype(int).tolist()}
        info: dict = {}
        if self.identification is not None:
            info["identification"] = self.identification.to_dict()
        if self.profile_weeks:
            info["profile_weeks"] = self.profile_weeks
        if self.reheat_scale is not None:
            info["reheat_scale"] = {b: float(v) for b, v in zip(structure.boxes,
                                                                self.reheat_scale)
                                    if b in self.site.boxes}
            info["reheat_from_faces"] = self.reheat_from_faces
        if self.reheat_leak is not None:
            leak = self.reheat_leak
            info["reheat_leak"] = {
                "method": "within time-of-week bins (Pipeline.fit_reheat_leak)",
                "rows": leak.rows,
                "zones": {z: {"k": float(leak.k[j]), "fitted": float(leak.fitted[j]),
                              "stderr": (float(leak.stderr[j]) if np.isfinite(leak.stderr[j])
                                         else None)}
                          for j, z in enumerate(structure.zones)}}
        params = self.params
        return write_model_file(
            path, site_file,
            parameters=None if params is None else dict(zip(params.param_names,
                                                            map(float, params.values))),
            weekly_profile=weekly_profile, model_options=model_options_dict(structure.options),
            structure=structure, room_volume=self.room_volume, extra={**info, **(extra or {})})

    # --- forecasts ---------------------------------------------------------------------
    @property
    def bundle(self) -> ModelBundle:
        """The model as the streaming estimator uses it (read from a model file)."""
        if self._bundle is None:
            raise PipelineError("no model file: write one with write_model_file() and use "
                                "Pipeline.from_model_file(path)")
        return self._bundle

    def forecast(self, telemetry: Telemetry | str | os.PathLike | pd.DataFrame,
                 times: Iterable, *, inputs: Mapping | None = None,
                 weather: Iterable | None = None, persistence: bool = False
                 ) -> dict[pd.Timestamp, Forecast]:
        """Day-ahead forecasts issued at ``times`` by the streaming estimator run over
        ``telemetry`` (:func:`~zonecast.estimator.streaming.offline_forecasts`, with its
        ``inputs``, ``weather`` forecasts and ``persistence``): the same numbers the
        service serves."""
        return offline_forecasts(self.bundle, telemetry, times, inputs=inputs,
                                 weather=weather, persistence=persistence)

    def forecast_variants(self, telemetry: Telemetry | str | os.PathLike | pd.DataFrame,
                          times: Iterable, variants: Mapping, *,
                          weather: Iterable | None = None
                          ) -> dict[str, dict[pd.Timestamp, Forecast]]:
        """Several day-ahead forecasts at each of ``times`` from one replay of
        ``telemetry`` (:func:`~zonecast.estimator.streaming.offline_forecast_variants`):
        name -> None (served), ``"persistence"`` or a mapping issue time -> inputs."""
        return offline_forecast_variants(self.bundle, telemetry, times, variants,
                                         weather=weather)
