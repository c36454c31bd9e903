"""Outside films of exterior faces from the site's wind climate.

An exterior face loses heat to the outdoors by convection, which grows with the wind at
the face, and by long-wave radiation. EnergyPlus computes the convection hour by hour with
the correlation its input names (``SurfaceConvectionAlgorithm:Outside``) from the weather
file's wind, reduced to the face's height on the building's terrain. The functions here
evaluate the same correlations on every hour of the building's weather file and return the
climate's mean film of each face [W/(m2 K)]: what ``ModelOptions(roof_exterior="climate")``
takes as the roofs' known film (docs/model.md "Roofs' own exterior"; measured against
EnergyPlus's own dry-hour films in docs/benchmarks.md "Outside films from the site's
wind").

Written here because no maintained Python library evaluates EnergyPlus's exterior
convection correlations; the equations are those of the EnergyPlus Engineering Reference,
"Outside Surface Heat Balance: Exterior Convection" (DOE-2, MoWiTT, SimpleCombined).

Pure functions first (one correlation each), then :func:`epw_wind` and
:func:`climate_films`, which apply them to a :class:`~zonecast.estimator.idf.Building`.
"""

from __future__ import annotations

import os

import numpy as np
from zonecast.estimator.idf import Building, local_wind

__all__ = [
    "NATURAL_DELTA_T",
    "ROUGHNESS_MULTIPLIER",
    "SIMPLE_COMBINED",
    "climate_film_parts",
    "climate_films",
    "doe2_convection",
    "epw_sun",
    "epw_wind",
    "long_wave_film",
    "mowitt_convection",
    "natural_convection",
    "simple_combined_film",
    "sunlit_film_parts",
    "windward",
]

#: roughness multiplier R_f of the DOE-2 correlation by the outer face's roughness [-]
#: (EnergyPlus Engineering Reference, "DOE-2 Model", after Walton 1981)
ROUGHNESS_MULTIPLIER = {"veryrough": 2.17, "rough": 1.67, "mediumrough": 1.52,
                        "mediumsmooth": 1.13, "smooth": 1.11, "verysmooth": 1.00}
#: coefficients (D [W/(m2 K)], E [J/(m3 K)], F [J s/(m4 K)]) of EnergyPlus's
#: ``SimpleCombined`` film h = D + E V + F V^2, convection and long-wave together, by
#: roughness (Engineering Reference, "Simple Combined", from the ASHRAE Handbook)
SIMPLE_COMBINED = {"veryrough": (11.58, 5.894, 0.0), "rough": (12.49, 4.065, 0.028),
                   "mediumrough": (10.79, 4.192, 0.0), "mediumsmooth": (8.23, 4.0, -0.057),
                   "smooth": (10.22, 3.1, 0.0), "verysmooth": (8.23, 3.33, -0.036)}
#: face-to-air temperature difference [K] at which the natural-convection part is taken:
#: the correlations grow as |dT|^(1/3), so 2-10 K give 0.8-1.3x the 5 K value, and the
#: forced part dominates at the wind of most hours
NATURAL_DELTA_T = 5.0
#: a face is windward when the wind comes from within this angle [deg] of its outward
#: normal (EnergyPlus); roofs and faces tilted less than 45 degrees are windward always
WINDWARD_ANGLE = 100.0
#: forced-convection constants (a [W/(m2 K (m/s)^b)], b [-]) of the MoWiTT and DOE-2
#: correlations, windward and leeward
_FORCED = {True: (3.26, 0.89), False: (3.55, 0.617)}
_SIGMA = 5.670374419e-8


def _roughness(roughness: str) -> str:
    key = str(roughness).replace(" ", "").lower()
    if key not in ROUGHNESS_MULTIPLIER:
        raise ValueError(f"roughness {roughness!r} is not one of EnergyPlus's "
                         "VeryRough, Rough, MediumRough, MediumSmooth, Smooth, VerySmooth")
    return key


def natural_convection(tilt, delta_t=NATURAL_DELTA_T, flow: str = "both") -> np.ndarray:
    """Walton's natural convection coefficient [W/(m2 K)] of a face tilted ``tilt`` [deg]
    (0 facing up) at a face-to-air difference ``delta_t`` [K]: 1.31 |dT|^(1/3) on a vertical
    face; on a tilted one the mean of the unstable (heat flowing up, 9.482 |dT|^(1/3) /
    (7.238 - |cos tilt|)) and the stable (1.810 |dT|^(1/3) / (1.382 + |cos tilt|)) cases, as
    a face of the outdoors is warmer than the air by day and colder at night; ``flow="up"``:
    the unstable case alone (a sunlit face warmer than the air). ``delta_t`` may be an
    array (one value per hour)."""
    c = np.abs(np.cos(np.radians(np.asarray(tilt, dtype=float))))
    cube = np.abs(np.asarray(delta_t, dtype=float)) ** (1.0 / 3.0)
    up = 9.482 * cube / (7.238 - c)
    tilted = up if flow == "up" else 0.5 * (up + 1.810 * cube / (1.382 + c))
    return np.where(c < 1e-6, 1.31 * cube, tilted)


def windward(wind_direction, azimuth: float, tilt: float) -> np.ndarray:
    """True where the wind from ``wind_direction`` [deg, from north, clockwise] strikes a
    face of outward azimuth ``azimuth`` [deg] (within :data:`WINDWARD_ANGLE`); always for
    a face tilted less than 45 degrees (roofs)."""
    d = np.asarray(wind_direction, dtype=float)
    if tilt < 45.0:
        return np.ones_like(d, dtype=bool)
    off = np.abs((d - azimuth + 180.0) % 360.0 - 180.0)
    return off <= WINDWARD_ANGLE


def doe2_convection(v_local, roughness: str, tilt: float, is_windward=True,
                    delta_t=NATURAL_DELTA_T, flow: str = "both") -> np.ndarray:
    """EnergyPlus's DOE-2 outside convection coefficient [W/(m2 K)]:
    h = h_n + R_f (sqrt(h_n^2 + (a V^b)^2) - h_n), with h_n Walton's natural convection
    (:func:`natural_convection`), R_f the roughness multiplier
    (:data:`ROUGHNESS_MULTIPLIER`) and (a, b) the windward or leeward MoWiTT constants, for
    the wind ``v_local`` [m/s] at the face."""
    v = np.maximum(np.asarray(v_local, dtype=float), 0.0)
    hn = natural_convection(tilt, delta_t, flow)
    ww = np.broadcast_to(np.asarray(is_windward, dtype=bool), v.shape)
    forced = np.where(ww, _FORCED[True][0] * v ** _FORCED[True][1],
                      _FORCED[False][0] * v ** _FORCED[False][1])
    glass = np.sqrt(hn ** 2 + forced ** 2)
    return hn + ROUGHNESS_MULTIPLIER[_roughness(roughness)] * (glass - hn)


def mowitt_convection(v_local, tilt: float, is_windward=True,
                      delta_t=NATURAL_DELTA_T, flow: str = "both") -> np.ndarray:
    """EnergyPlus's MoWiTT outside convection coefficient [W/(m2 K)]: the DOE-2 form for a
    smooth (glass) face, sqrt(h_n^2 + (a V^b)^2), with Walton's natural part."""
    v = np.maximum(np.asarray(v_local, dtype=float), 0.0)
    hn = natural_convection(tilt, delta_t, flow)
    ww = np.broadcast_to(np.asarray(is_windward, dtype=bool), v.shape)
    forced = np.where(ww, _FORCED[True][0] * v ** _FORCED[True][1],
                      _FORCED[False][0] * v ** _FORCED[False][1])
    return np.sqrt(hn ** 2 + forced ** 2)


def simple_combined_film(v_local, roughness: str) -> np.ndarray:
    """EnergyPlus's ``SimpleCombined`` outside film [W/(m2 K)], convection and long-wave
    together: D + E V + F V^2 for the wind ``v_local`` [m/s] at the face
    (:data:`SIMPLE_COMBINED`)."""
    v = np.maximum(np.asarray(v_local, dtype=float), 0.0)
    d, e, f = SIMPLE_COMBINED[_roughness(roughness)]
    return d + e * v + f * v ** 2


def long_wave_film(mean_air_temperature: float, emissivity: float = 0.9) -> float:
    """Linearised long-wave coefficient [W/(m2 K)] of an exterior face to its surroundings,
    4 eps sigma T^3 at the climate's mean air temperature [degC]."""
    t = mean_air_temperature + 273.15
    return float(4.0 * emissivity * _SIGMA * t ** 3)


#: EPW data fields (0-based) and their missing-value codes: dry-bulb [degC], horizontal
#: infrared from the sky [W/m2], global horizontal irradiance [Wh/m2], wind direction
#: [deg] and speed [m/s] (EnergyPlus Auxiliary Programs, "Weather Converter")
_EPW_FIELDS = {"air": (6, 99.9), "ir": (12, 9999.0), "ghi": (13, 9999.0),
               "direction": (20, 999.0), "speed": (21, 999.0)}


def _epw_columns(path: str | os.PathLike, names) -> dict[str, np.ndarray]:
    """The named :data:`_EPW_FIELDS` of an EPW file's data rows, on the rows where every
    one of them is present."""
    rows: dict[str, list[float]] = {k: [] for k in names}
    with open(path, encoding="latin-1") as fh:
        for i, line in enumerate(fh):
            if i < 8:
                continue
            f = line.split(",")
            if len(f) < 22:
                continue
            for k in names:
                rows[k].append(float(f[_EPW_FIELDS[k][0]]))
    if not rows[names[0]]:
        raise ValueError(f"{path} has no EPW data rows: give an EPW weather file")
    out = {k: np.asarray(v, dtype=float) for k, v in rows.items()}
    ok = np.logical_and.reduce([out[k] < _EPW_FIELDS[k][1] for k in names])
    return {k: v[ok] for k, v in out.items()}


def epw_wind(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Hourly wind speed [m/s], wind direction [deg] and dry-bulb temperature [degC] of an
    EPW weather file (fields 22, 21 and 7 of its data rows)."""
    c = _epw_columns(path, ("speed", "direction", "air"))
    return c["speed"], c["direction"], c["air"]


def epw_sun(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """Hourly columns of an EPW weather file for a face's sunlit balance, on the rows where
    every one is present: ``speed`` [m/s], ``direction`` [deg], ``air`` [degC] (fields 22,
    21, 7), ``ir`` the horizontal infrared radiation from the sky [W/m2] (field 13) and
    ``ghi`` the global horizontal irradiance [Wh/m2 over the hour] (field 14)."""
    return _epw_columns(path, ("air", "ir", "ghi", "direction", "speed"))


def sunlit_film_parts(speed, direction, air, ir, ghi, *, tilt: float, azimuth: float,
                      roughness: str, emissivity: float, absorptance: float,
                      algorithm: str = "doe2", height_factor: float = 1.0,
                      iterations: int = 4) -> tuple[float, float]:
    """(convection, long-wave) [W/(m2 K)] of a sunlit face, weighted by the sun it absorbs:
    each hour's films at the face's own temperature, sum_t a I_t h_t / sum_t a I_t.

    The hour's face-to-air difference is the steady sol-air balance of a well insulated
    face, dT = (a I - h_r (T_a - T_sky)) / (h_c + h_r) (iterated, as the films depend on
    it), with the global horizontal irradiance I, the sky's temperature from the file's
    horizontal infrared (T_sky = (IR / sigma)^(1/4)), the natural convection of heat flowing
    up (:func:`natural_convection`, ``flow="up"``) and the linearised long-wave
    h_r = 4 eps sigma T_m^3 at the mean of the face's and the sky's temperatures. A sunlit
    roof runs 15-40 K above the air, so its films are larger than the climate's mean
    (natural convection grows as dT^(1/3), long-wave as T^3): the film that carries the
    sun's heat."""
    w = absorptance * np.maximum(np.asarray(ghi, float), 0.0)
    if not w.sum() > 0:
        raise ValueError("the weather file has no sun: give an EPW with irradiance")
    sun = w > 0
    v = np.asarray(speed, float)[sun] * height_factor
    ta = np.asarray(air, float)[sun] + 273.15
    t_sky = (np.maximum(np.asarray(ir, float)[sun], 1.0) / _SIGMA) ** 0.25
    ww = windward(np.asarray(direction, float)[sun], azimuth, tilt)
    w = w[sun]
    dt = np.full(len(w), NATURAL_DELTA_T)
    for _ in range(iterations):
        t_m = 0.5 * (ta + dt + t_sky)
        h_r = 4.0 * emissivity * _SIGMA * t_m ** 3
        h_c = (mowitt_convection(v, tilt, ww, dt, "up") if algorithm == "mowitt"
               else doe2_convection(v, roughness, tilt, ww, dt, "up"))
        dt = np.maximum((w - h_r * (ta - t_sky)) / (h_c + h_r), 0.0)
    return float(np.sum(w * h_c) / w.sum()), float(np.sum(w * h_r) / w.sum())


def _height(vertices: np.ndarray) -> float:
    return float(np.mean(np.asarray(vertices, dtype=float)[:, 2]))


def climate_films(building: Building, surfaces=None,
                  weather_file: str | os.PathLike | None = None) -> dict[str, float]:
    """The climate's mean outside film [W/(m2 K)] of each exterior face: convection and
    long-wave to the air together, the sum of :func:`climate_film_parts`."""
    return {n: c + r for n, (c, r) in
            climate_film_parts(building, surfaces, weather_file).items()}


def climate_film_parts(building: Building, surfaces=None,
                       weather_file: str | os.PathLike | None = None,
                       weight: str = "hours") -> dict[str, tuple[float, float]]:
    """The climate's mean outside film [W/(m2 K)] of each exterior face of ``building``
    (``surfaces``: their names; default every opaque surface open to the outdoors), as
    (convection, long-wave): the long-wave part linearised at the weather file's mean air
    temperature; ``(combined, 0.0)`` for ``SimpleCombined``, whose one coefficient holds
    both and whose faces EnergyPlus links to the air alone (no sky exchange).

    Every hour of the weather file (``weather_file``, default
    :attr:`~zonecast.estimator.idf.Building.weather_file`) gives the wind at the face's
    mean height on the building's terrain (:func:`~zonecast.estimator.idf.local_wind`) and
    the building's outside correlation (:attr:`Building.outside_convection`) the film:
    ``SimpleCombined`` as it is (it holds the long-wave part); ``DOE-2`` (EnergyPlus's
    default; also taken for ``TARP`` and ``AdaptiveConvectionAlgorithm``, said in the
    notes) and ``MoWiTT`` plus :func:`long_wave_film` with the outer layer's emissivity. The
    mean over the hours is the film. EnergyPlus's wet hours (rain, when it sets the
    convection to 1000 W/(m2 K)) are not in it. ``weight="sun"``: the films that carry the
    sun's heat instead (:func:`sunlit_film_parts`; SimpleCombined as with "hours").

    Raises
    ------
    ValueError
        Without a weather file, with what to give.
    """
    source = weather_file if weather_file is not None else building.weather_file
    if source is None:
        raise ValueError("the outside films follow the site's wind, and no weather file is "
                         "known: give the site's weather_file (the EPW the building is "
                         "simulated with)")
    if weight not in ("hours", "sun"):
        raise ValueError(f"weight={weight!r}: use 'hours' or 'sun'")
    speed, direction, air = epw_wind(source)
    sun = epw_sun(source) if weight == "sun" else None
    algo = str(building.outside_convection).replace("-", "").lower()
    if algo in ("tarp", "adaptiveconvectionalgorithm"):
        note = (f"outside films: {building.outside_convection}'s correlations are taken as "
                "DOE-2's (EnergyPlus's default)")
        if note not in building.notes:
            building.notes.append(note)
    names = surfaces if surfaces is not None else [
        n for n, s in building.surfaces.items() if s.boundary == "Outdoors"]
    films = {}
    for name in names:
        s = building.surfaces[name]
        layers = building.constructions[s.construction].layers
        rough = layers[0].roughness if layers else "MediumRough"
        emissivity = layers[0].thermal_absorptance if layers else 0.9
        v = speed * local_wind(1.0, _height(s.vertices), building.terrain)
        if algo == "simplecombined":
            films[name] = (float(np.mean(simple_combined_film(v, rough))), 0.0)
            continue
        if sun is not None:
            films[name] = sunlit_film_parts(
                sun["speed"], sun["direction"], sun["air"], sun["ir"], sun["ghi"],
                tilt=s.tilt, azimuth=s.azimuth, roughness=rough, emissivity=emissivity,
                absorptance=layers[0].solar_absorptance if layers else 0.7,
                algorithm="mowitt" if algo == "mowitt" else "doe2",
                height_factor=local_wind(1.0, _height(s.vertices), building.terrain))
            continue
        ww = windward(direction, s.azimuth, s.tilt)
        h = (mowitt_convection(v, s.tilt, ww) if algo == "mowitt"
             else doe2_convection(v, rough, s.tilt, ww))
        films[name] = (float(np.mean(h)), long_wave_film(float(np.mean(air)), emissivity))
    return films

