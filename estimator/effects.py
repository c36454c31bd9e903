"""Candidate unmodelled effects for the sim-to-real diagnosis (``zonecast diagnose``).

Each effect is a physically meaningful term the paper's 13-parameter model lacks, with one
parameter per model zone (``supply_offset``: one for the whole system):

========================  ==========  ====================================================
name                      parameter   extra term in zone z
========================  ==========  ====================================================
``reheat``                W/K         heat q = θ · m_z(k) · max(0, T_h − T_z): reheat coils of
                                      boxes at minimum airflow (fraction m_z of the zone's
                                      boxes) acting as proportional heating to T_h; T_h is
                                      the site's scheduled heating set point (variant
                                      ``"schedule"``, when the site gives its thermostat)
                                      or searched over :data:`REHEAT_SETPOINTS`
``infiltration``          W/K         heat q = θ · (T_a − T_z) (outdoor air leaking in)
``window_solar``          -           heat q = θ · Σ_f a_win,z,f · I_f(k) through a first-order
                                      lag τ (transmitted solar stored in floors and
                                      furniture before it reaches the air); τ in
                                      :data:`SOLAR_LAGS`
``occupancy_gains``       W/m2        heat q = θ · a_floor,z · 1[workday, 08:00–18:00 local]
                                      (variant None), or, variant ``"profile"`` (with a
                                      reference period's gains), q = θ · a_floor,z · g_z(k) /
                                      mean(g_z): the zone's own internal gains g = c_IG +
                                      f_IG,profile scaled (more or fewer people, lights,
                                      equipment than in the reference period)
``supply_offset``         K           heat q = θ · c_p · Σ_{boxes of z} u_j (supply air at the
                                      boxes θ warmer than the AHU sensor reads); one θ for
                                      all zones: the site has one supply temperature point
``interzone_air``         W/K         air exchanged both ways between each room of zone z
                                      and each adjacent room of another zone (open doors,
                                      transfer grilles, EnergyPlus ZoneCrossMixing): a
                                      conductance θ = c_p·ṁ between the two rooms' air
                                      added to the network
                                      (:func:`~.diagnose.exchanged_air`); linearised, z
                                      gains θ · Σ_n p_zn (T_n − T_z) and each neighbour n
                                      loses θ · p_zn (T_n − T_z), p_zn the adjacent room
                                      pairs (:func:`interzone_exchange`)
``sensor_bias``           K           measured ȳ_z = C_z x + θ (output equation)
``thermal_mass``          -           area of the zone's internal mass (furniture,
                                      partitions) scaled by (1 + θ): the model rebuilt
                                      from the building with that area, so its capacity,
                                      its exchange with the room and its share of the
                                      window solar and radiant gains all follow
                                      (:func:`~.diagnose.furniture_rebuilder`); without
                                      the building, its own nodes scaled
                                      (:func:`~.diagnose.scaled_internal_mass`); no term
                                      in a zone without internal mass
========================  ==========  ====================================================

The heat terms enter the model like internal gains (spread over the zone's rooms by floor
area, paper eq:q_ig), so every term is linear in its parameter once the temperatures T_z in
the regressor are taken from the model's own prediction (Gauss-Newton linearisation around
the base model; nothing measured after a forecast's issue time enters a regressor).

Pure functions of the data and the model structure; :mod:`.diagnose` turns them into
output sensitivities and scores. Names are stable: they are keys of ``diagnosis.json``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from zonecast.estimator.dataset import ModelData
from zonecast.estimator.forecast import fill_profile, zone_floor_area
from zonecast.estimator.gains import fit_weekly_profile
from zonecast.estimator.model import BilinearModel
from zonecast.estimator.rc.network import CP_AIR as C_P

__all__ = [
    "EFFECTS",
    "GAINS_PROFILE",
    "REHEAT_SETPOINTS",
    "SCHEDULE",
    "SOLAR_LAGS",
    "SPECS",
    "EffectSpec",
    "adjacent_rooms",
    "adjacent_zones",
    "box_zone_matrix",
    "exchange_pairs",
    "first_order_lag",
    "heat_regressor",
    "interzone_exchange",
    "minimum_airflow_fraction",
    "time_of_week_mean",
    "window_area_by_facade",
]

#: heating setpoints searched for the reheat term [degC]
REHEAT_SETPOINTS = (19.0, 20.0, 21.0, 22.0)
#: reheat variant that follows the site's thermostat schedule (``Site.thermostat``)
SCHEDULE = "schedule"
#: lags of transmitted solar reaching the air [h] (0: at once)
SOLAR_LAGS = (0.0, 2.0, 6.0)
#: occupancy-gains variant shaped as the zone's internal-gains profile (needs a reference)
GAINS_PROFILE = "profile"
#: a box counts as at its minimum when its airflow is within this factor of its 1st percentile
MIN_FLOW_FACTOR = 1.05


@dataclass(frozen=True)
class EffectSpec:
    """One candidate effect.

    Attributes
    ----------
    name : stable identifier
    kind : ``"heat"`` (extra heat into the zone's air), ``"output"`` (measurement model) or
        ``"capacity"`` (scaled heat capacity)
    unit : unit of the per-zone parameter
    sign : +1 when only a non-negative parameter is physical, 0 when either sign is
    variants : hyper-parameter values searched (setpoint, lag), ``(None,)`` if none
    description : one line for reports
    scope : ``"zone"`` (one parameter per zone) or ``"system"`` (one parameter shared by
        every zone: the effect belongs to equipment common to all of them)
    """

    name: str
    kind: str
    unit: str
    sign: int
    variants: tuple
    description: str
    scope: str = "zone"


SPECS: dict[str, EffectSpec] = {s.name: s for s in (
    EffectSpec("reheat", "heat", "W/K", +1, (SCHEDULE, *REHEAT_SETPOINTS),
               "VAV reheat at minimum airflow, proportional to the shortfall below a setpoint"),
    EffectSpec("infiltration", "heat", "W/K", +1, (None,),
               "outdoor air leaking in, proportional to outdoor minus zone temperature"),
    EffectSpec("window_solar", "heat", "-", 0, SOLAR_LAGS,
               "transmitted window solar reaching the air through floor/furniture storage"),
    EffectSpec("occupancy_gains", "heat", "W/m2", 0, (None, GAINS_PROFILE),
               "a gain on workdays 08:00-18:00 local (office occupancy), or the zone's "
               "internal gains scaled (variant 'profile')"),
    EffectSpec("supply_offset", "heat", "K", 0, (None,),
               "supply air at the boxes warmer or colder than the AHU sensor reads",
               scope="system"),
    EffectSpec("interzone_air", "heat", "W/K", +1, (None,),
               "air exchanged both ways with adjacent zones (open doors, transfer grilles)"),
    EffectSpec("sensor_bias", "output", "K", 0, (None,),
               "constant offset of the zone temperature sensors"),
    EffectSpec("thermal_mass", "capacity", "-", 0, (None,),
               "internal mass (furniture) area scaled by (1 + parameter)"),
)}
#: effect names in a stable order
EFFECTS = tuple(SPECS)


def box_zone_matrix(model: BilinearModel) -> np.ndarray:
    """(n_boxes, n_zones) 1 where a box serves a room of the zone (a scheduled input,
    e.g. an infiltration that follows a schedule, is not a box: a row of zeros)."""
    st = model.structure
    zone_of_room = {r: j for j, z in enumerate(st.zones) for r in st.zones[z]}
    M = np.zeros((len(st.boxes), len(st.zones)))
    for i, (box, room) in enumerate(st.boxes.items()):
        if box not in st.scheduled:
            M[i, zone_of_room[room]] = 1.0
    return M


def minimum_airflow_fraction(u: np.ndarray, bz: np.ndarray) -> np.ndarray:
    """(N, n_zones) fraction of each zone's boxes running at their minimum airflow.

    A box's minimum is the 1st percentile of its positive airflow readings; readings within
    :data:`MIN_FLOW_FACTOR` of it count as at minimum.
    """
    u = np.asarray(u, float)
    lo = np.array([np.percentile(col[col > 0], 1) if (col > 0).any() else 0.0 for col in u.T])
    at_min = (u <= lo * MIN_FLOW_FACTOR).astype(float)
    n = bz.sum(axis=0)
    return (at_min @ bz) / np.where(n > 0, n, 1.0)


def window_area_by_facade(model: BilinearModel) -> np.ndarray:
    """(n_zones, 4) exterior window area of each zone per facade E, S, W, N [m2]
    (the structure's window solar weights, :attr:`RCStructure.window_area`)."""
    st = model.structure
    out = np.zeros((len(st.zones), 4))
    for j, z in enumerate(st.zones):
        for r in st.zones[z]:
            out[j] += st.window_area.get(r, 0.0)
    return out


def adjacent_rooms(model: BilinearModel) -> np.ndarray:
    """(n_rooms, n_rooms) 1 where two rooms of different model zones share an interzone
    element (wall, floor); rows and columns in the order of ``structure.rooms`` (the air
    states), rooms outside every model zone (plenums) have none."""
    st = model.structure
    A = st.A(model.params.physical).tocsc()
    zone_of_room = {r: j for j, z in enumerate(st.zones) for r in st.zones[z]}
    air_zone = {i: zone_of_room[r] for i, r in enumerate(st.rooms) if r in zone_of_room}
    by_element: dict[str, list[int]] = {}
    for j, lab in enumerate(st.labels):
        if lab.element:
            by_element.setdefault(lab.element, []).append(j)
    adj = np.zeros((len(st.rooms), len(st.rooms)))
    for nodes in by_element.values():
        rows = {i for i in A[:, nodes].nonzero()[0] if i in air_zone}
        for a in rows:
            for b in rows:
                if air_zone[a] != air_zone[b]:
                    adj[a, b] = 1.0
    return adj


def _room_zone_matrix(model: BilinearModel) -> np.ndarray:
    """(n_rooms, n_zones) 1 where an air state's room belongs to the zone."""
    st = model.structure
    M = np.zeros((len(st.rooms), len(st.zones)))
    index = {r: i for i, r in enumerate(st.rooms)}
    for j, z in enumerate(st.zones):
        for r in st.zones[z]:
            M[index[r], j] = 1.0
    return M


def adjacent_zones(model: BilinearModel) -> np.ndarray:
    """(n_zones, n_zones) 1 where two zones share an interzone element (wall, floor)."""
    return (exchange_pairs(model) > 0).astype(float)


def exchange_pairs(model: BilinearModel) -> np.ndarray:
    """(n_zones, n_zones) number of adjacent room pairs (:func:`adjacent_rooms`) between
    two zones: the openings an exchange of air per pair of rooms passes through."""
    M = _room_zone_matrix(model)
    return M.T @ adjacent_rooms(model) @ M


def interzone_exchange(adj: np.ndarray, temps: np.ndarray) -> np.ndarray:
    """(N, n_zones, n_zones) heat into each zone per unit exchange of each zone [W per W/K].

    ``[k, i, j]`` is what zone i receives at row k when zone j exchanges air with its
    adjacent zones at a unit conductance c_p·ṁ = 1 W/K per opening (``adj[j, n]``: the
    openings between zones j and n, :func:`exchange_pairs`, or 1 per adjacent zone,
    :func:`adjacent_zones`):
    zone j gains Σ_n adj[j, n] (T_n − T_j) and each neighbour n loses adj[j, n] (T_n − T_j),
    as EnergyPlus's ZoneCrossMixing moves the same air both ways. Every column sums to zero
    over i (the exchange conserves heat). ``temps`` (N, n_zones) [degC].
    """
    adj = np.asarray(adj, float)
    temps = np.asarray(temps, float)
    nz = adj.shape[0]
    if adj.shape != (nz, nz) or temps.ndim != 2 or temps.shape[1] != nz:
        raise ValueError(f"adj must be (n_zones, n_zones) and temps (N, n_zones); got "
                         f"{adj.shape} and {temps.shape}")
    # flow[k, j, n]: heat zone j takes from neighbour n per unit exchange of zone j
    flow = adj[None, :, :] * (temps[:, None, :] - temps[:, :, None])
    out = -flow.transpose(0, 2, 1)
    idx = np.arange(nz)
    out[:, idx, idx] = flow.sum(axis=2)
    return out


def first_order_lag(x: np.ndarray, tau_h: float, step_s: float,
                    segments: list[tuple[int, int]]) -> np.ndarray:
    """x through a unit-gain first-order lag of time constant ``tau_h`` [h], restarted at
    every data segment; ``tau_h = 0`` returns x."""
    x = np.asarray(x, float)
    if tau_h <= 0:
        return x.copy()
    a = float(np.exp(-step_s / (tau_h * 3600.0)))
    out = np.empty_like(x)
    for s0, s1 in segments:
        acc = x[s0].copy()
        for k in range(s0, s1):
            acc = a * acc + (1 - a) * x[k]
            out[k] = acc
    return out


def _workday_hours(data: ModelData) -> np.ndarray:
    local = data.local_times()
    return ((local.day_of_week < 5) & (local.hour >= 8) & (local.hour < 18)).astype(float)


def heat_regressor(name: str, variant, model: BilinearModel, data: ModelData,
                   temps: np.ndarray, heating_setpoint: np.ndarray | None = None,
                   gains: np.ndarray | None = None) -> np.ndarray:
    """(N, n_zones) extra heat into each zone per unit parameter [W per unit].

    ``temps`` (N, n_zones) are the zone temperatures the regressor uses [degC]: the base
    model's own prediction (see the module docstring), never measurements after an issue
    time. Rows where ``temps`` is NaN give NaN. ``heating_setpoint`` (N,) [degC]: the
    site's scheduled heating set point, needed by the reheat variant ``"schedule"``
    (:meth:`~.site.Thermostat.heating_setpoint`). ``gains`` (N, n_zones) [W/m2]: the
    internal gains c_IG + f_IG the base model uses, needed by the occupancy-gains variant
    ``"profile"`` (its shape, scaled to a mean of one over the rows; a zone whose mean is
    not positive gets no term).
    """
    spec = SPECS.get(name)
    if spec is None or spec.kind != "heat":
        heat = [n for n, s in SPECS.items() if s.kind == "heat"]
        raise ValueError(f"unknown heat effect {name!r}; heat effects are {heat}")
    N, nz = len(data), model.n_zones
    temps = np.asarray(temps, float)
    if temps.shape != (N, nz):
        raise ValueError(f"temps must have shape {(N, nz)}, got {temps.shape}")
    bz = box_zone_matrix(model)
    if name == "reheat":
        if variant == SCHEDULE:
            if heating_setpoint is None:
                raise ValueError("the reheat variant 'schedule' needs the site's heating set "
                                 "point schedule (site.yaml 'thermostat')")
            th = np.asarray(heating_setpoint, float)
            if th.shape != (N,):
                raise ValueError(f"heating_setpoint must have shape {(N,)}, got {th.shape}")
            th = th[:, None]
        else:
            th = float(variant)
        return minimum_airflow_fraction(data.u, bz) * np.maximum(0.0, th - temps)
    if name == "infiltration":
        return data.v[:, [0]] - temps
    if name == "window_solar":
        q = data.v[:, 2:6] @ window_area_by_facade(model).T
        step = (data.times[1] - data.times[0]).total_seconds()
        return first_order_lag(q, float(variant), step, data.segments)
    if name == "occupancy_gains":
        if variant == GAINS_PROFILE:
            if gains is None:
                raise ValueError("the occupancy-gains variant 'profile' needs the base "
                                 "model's internal gains (a reference period's profile)")
            g = np.asarray(gains, float)
            if g.shape != (N, nz):
                raise ValueError(f"gains must have shape {(N, nz)}, got {g.shape}")
            mean = np.nanmean(g, axis=0)
            shape = np.where(mean > 0, g / np.where(mean > 0, mean, 1.0), 0.0)
            return np.nan_to_num(shape) * zone_floor_area(model)[None, :]
        return _workday_hours(data)[:, None] * zone_floor_area(model)[None, :]
    if name == "supply_offset":
        return C_P * (data.u @ bz)
    if name == "interzone_air":
        adj = exchange_pairs(model)
        return temps @ adj.T - temps * adj.sum(axis=1)[None, :]
    raise AssertionError(name)  # every heat effect is handled above


def time_of_week_mean(values: np.ndarray, data: ModelData, rows: np.ndarray) -> np.ndarray:
    """(N, k) what a weekly internal-gains profile fitted on ``rows`` absorbs of an extra
    term: ``values`` averaged as paper Eq:fixed_ig (:func:`~.gains.fit_weekly_profile`,
    empty bins filled as :func:`~.forecast.fill_profile`), evaluated at every row."""
    step = data.times[1] - data.times[0]
    prof = fit_weekly_profile(data.times[rows], np.asarray(values, float)[rows], data.timezone,
                              step=step)
    return np.nan_to_num(fill_profile(prof)(data.times))
