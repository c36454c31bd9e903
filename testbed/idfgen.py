"""Building config -> EnergyPlus input (IDF, Version 25.2).

HVAC is written with EnergyPlus's own HVACTemplate objects (expanded by ExpandObjects
at run time): one AHU (chilled-water cooling with outdoor-air reset of the supply set
point, electric heating coil, economiser) serving one VAV box with electric reheat per
room; a room with several boxes (``Room.box_shares``) gets the others added to the
expanded IDF (:func:`zonecast.testbed.run.add_boxes`). Box airflows are forced exactly by ``Zone Minimum Air Flow Input Method =
Scheduled`` with the minimum fraction from a Schedule:File column per box; during an
excitation block the shared thermostat is widened so that no box modulates above its
scheduled fraction.
"""

from __future__ import annotations

import datetime as dt

from zonecast.testbed.config import BuildingConfig
from zonecast.testbed.effects import Effects
from zonecast.testbed.geometry import plan_walls, wall_vertices, window_on

SCHEDULE_FILE = "schedules.csv"

OUTPUT_VARIABLES = [
    ("*", "Zone Mean Air Temperature"),
    ("*", "Zone People Total Heating Rate"),
    ("*", "Zone People Sensible Heating Rate"),
    ("*", "Zone Lights Total Heating Rate"),
    ("*", "Zone Electric Equipment Total Heating Rate"),
    ("*", "Zone Infiltration Sensible Heat Gain Energy"),
    ("*", "Zone Infiltration Sensible Heat Loss Energy"),
    ("*", "Surface Window Transmitted Solar Radiation Rate"),
    ("*", "Heating Coil Heating Rate"),
    ("*", "Site Outdoor Air Drybulb Temperature"),
    ("*", "Site Direct Solar Radiation Rate per Area"),
    ("*", "Site Diffuse Solar Radiation Rate per Area"),
    ("*", "Site Solar Altitude Angle"),
]


def obj(cls: str, *fields) -> str:
    vals = ["" if f is None else (f"{f:.6g}" if isinstance(f, float) else str(f)) for f in fields]
    if not vals:
        return f"{cls};\n"
    body = ",\n".join(f"    {v}" for v in vals[:-1])
    return f"{cls},\n{body + ',' if body else ''}\n    {vals[-1]};\n".replace(",\n\n", ",\n")


def box_name(room: str, i: int = 0) -> str:
    """The BMS name of box ``i`` of ``room`` (the first keeps the one-box name)."""
    return f"VAV_{room}" if i == 0 else f"VAV_{room}_{i + 1}"


def supply_node(room: str, i: int = 0) -> str:
    """The air outlet node of box ``i`` of ``room`` (box 0: the zone air inlet node
    HVACTemplate:Zone:VAV gives it)."""
    return f"{room} Supply Inlet" if i == 0 else f"{room} Supply Inlet {i + 1}"


def reheat_coil(room: str, i: int = 0) -> str:
    """The electric reheat coil of box ``i`` of ``room``."""
    return f"{room} Reheat Coil" if i == 0 else f"{room} Reheat Coil {i + 1}"


def room_boxes(cfg: BuildingConfig, room: str) -> list[tuple[int, str, float]]:
    """(index, BMS name, share of the room's design airflow) of every box of ``room``."""
    return [(i, box_name(room, i), share)
            for i, share in enumerate(cfg.rooms[room].box_shares)]


def ahu_outlet_node() -> str:
    return "AHU Supply Fan Outlet"


def build_idf(cfg: BuildingConfig, periods: list[tuple[dt.date, dt.date]], effects: Effects,
              columns: list[str]) -> str:
    """IDF text for ``cfg`` simulating each (first day, last day) run period.

    ``columns`` are the schedule table's column names, in file order.
    """
    col = {c: i + 1 for i, c in enumerate(columns)}
    H = cfg.floor_to_ceiling
    walls = plan_walls({n: r.rect for n, r in cfg.rooms.items()})
    out: list[str] = ["! zonecast virtual building " + cfg.name + "\n"]
    add = out.append
    add(obj("Version", "25.2"))
    add(obj("SimulationControl", "Yes", "Yes", "Yes", "No", "Yes", "No", 1))
    add(obj("Building", cfg.name, float(cfg.north_axis), "City", 0.04, 0.4, "FullExterior", 25, 6))
    add(obj("Timestep", 4))
    if effects.inside_convection == "simple":  # constant inside films (default TARP)
        add(obj("SurfaceConvectionAlgorithm:Inside", "Simple"))
    if cfg.shading is not None:  # shadows of overhangs and fins recomputed every day
        add(obj("ShadowCalculation", "PolygonClipping", "Periodic", 1))
    add(obj("Site:Location", cfg.name + " site", cfg.location.latitude, cfg.location.longitude,
            cfg.location.standard_offset_hours, cfg.location.elevation))
    if cfg.floor_position == "ground":
        add(obj("Site:GroundTemperature:BuildingSurface", *cfg.ground_temperature))
    add(obj("SizingPeriod:WeatherFileDays", "Summer sizing", 9, 1, 9, 14, "Monday", "No", "No"))
    add(obj("SizingPeriod:WeatherFileDays", "Winter sizing", 1, 5, 1, 18, "Monday", "No", "No"))
    for i, (first, last) in enumerate(periods):
        add(obj("RunPeriod", f"Period {i}", first.month, first.day, first.year, last.month,
                last.day, last.year, "", "No", "No", "No", "Yes", "Yes", "No", "Hour24"))
    add(obj("RunPeriodControl:DaylightSavingTime", "2nd Sunday in March", "1st Sunday in November"))
    # EnergyPlus ignores the Building North Axis under World coordinates (it warns "any
    # non-zero Building/Zone North Axes ... are ignored"); a rotated plan therefore uses
    # Relative coordinates, which equal World ones here (every zone origin is 0, 0, 0).
    add(obj("GlobalGeometryRules", "UpperLeftCorner", "Counterclockwise",
            "World" if cfg.north_axis == 0 else "Relative"))
    # materials and constructions
    seen = set()
    for cname, layers in cfg.constructions.items():
        for layer in layers:
            if layer[0] in seen:
                continue
            seen.add(layer[0])
            if len(layer) == 2:
                add(obj("Material:NoMass", layer[0], "Smooth", float(layer[1]), 0.9, 0.6, 0.6))
            else:
                name, th, k, rho, c = layer
                add(obj("Material", name, "MediumRough", float(th), float(k), float(rho), float(c),
                        0.9, 0.65, 0.65))
        add(obj("Construction", cname, *[layer[0] for layer in layers]))
    if cfg.plenum is not None:
        # the rooms' ceiling is its last layer (the tile) under the plenum; above the plenum
        # the ceiling's (or the roof's) massive layers without the tile and air spaces
        tile = cfg.constructions["ceiling"][-1]
        add(obj("Construction", "plenum_tile", tile[0]))
        top = cfg.constructions["roof" if cfg.floor_position == "top" else "ceiling"]
        deck = [layer[0] for layer in top[:-1] if len(layer) != 2] or [top[0][0]]
        add(obj("Construction", "plenum_deck", *deck))
    shgc = effects.shgc if effects.shgc is not None else cfg.glazing.shgc
    add(obj("WindowMaterial:SimpleGlazingSystem", "Glazing", cfg.glazing.u_factor, shgc,
            cfg.glazing.visible_transmittance))
    add(obj("Construction", "window", "Glazing"))
    # schedules
    add(obj("ScheduleTypeLimits", "Fraction", 0.0, 1.0, "Continuous"))
    add(obj("ScheduleTypeLimits", "Temperature", -60.0, 200.0, "Continuous"))
    add(obj("ScheduleTypeLimits", "Any Number"))
    add(obj("Schedule:Constant", "AlwaysOn", "Fraction", 1.0))
    add(obj("Schedule:Constant", "AlwaysOff", "Fraction", 0.0))
    add(obj("Schedule:Constant", "Activity", "Any Number", 120.0))
    if effects.sky == "dry_bulb":
        # the sky at the outdoor air: no long-wave deficit at any exterior face
        add(obj("Schedule:Constant", "Sky Below Dry Bulb", "Any Number", 0.0))
        add(obj("WeatherProperty:SkyTemperature", "", "DifferenceScheduleDryBulbValue",
                "Sky Below Dry Bulb", "No"))
    for name in columns:
        limits = "Temperature" if name in ("htg", "clg") else "Fraction"
        add(obj("Schedule:File", f"sch:{name}", limits, SCHEDULE_FILE, col[name], 1, 8760,
                "Comma", "No", 15, "Yes"))
    # zones, surfaces, gains
    for rname, room in cfg.rooms.items():
        x0, y0, x1, y1 = room.rect
        add(obj("Zone", rname, 0.0, 0.0, 0.0, 0.0, 1, 1, H, "autocalculate", "autocalculate"))
        add(obj("BuildingSurface:Detailed", f"{rname}_Floor", "Floor", "floor", rname, "",
                "Ground" if cfg.floor_position == "ground" else "Adiabatic", "", "NoSun",
                "NoWind", "", 4,
                x0, y1, 0.0, x1, y1, 0.0, x1, y0, 0.0, x0, y0, 0.0))
        if cfg.plenum is not None:
            add(obj("BuildingSurface:Detailed", f"{rname}_Ceiling", "Ceiling", "plenum_tile",
                    rname, "", "Surface", f"Plenum_Floor_{rname}", "NoSun", "NoWind", "", 4,
                    x0, y0, H, x1, y0, H, x1, y1, H, x0, y1, H))
        elif cfg.floor_position == "top":
            add(obj("BuildingSurface:Detailed", f"{rname}_Roof", "Roof", "roof", rname, "",
                    "Outdoors", "", "SunExposed", "WindExposed", "", 4,
                    x0, y0, H, x1, y0, H, x1, y1, H, x0, y1, H))
        else:
            add(obj("BuildingSurface:Detailed", f"{rname}_Ceiling", "Ceiling", "ceiling", rname,
                    "", "Adiabatic", "", "NoSun", "NoWind", "", 4,
                    x0, y0, H, x1, y0, H, x1, y1, H, x0, y1, H))
        for w in walls[rname].walls:
            ext = w.neighbour is None
            v = [c for p in wall_vertices(w, 0.0, H) for c in p]
            add(obj("BuildingSurface:Detailed", w.name, "Wall",
                    "exterior_wall" if ext else "interior_wall", rname, "",
                    "Outdoors" if ext else "Surface", "" if ext else w.partner,
                    "SunExposed" if ext else "NoSun", "WindExposed" if ext else "NoWind",
                    "", 4, *v))
            if ext and room.windows:
                win = window_on(w, H, cfg.window_to_wall_ratio)
                if win:
                    v = [c for p in wall_vertices(w, 0.0, H, win) for c in p]
                    add(obj("FenestrationSurface:Detailed", f"{w.name}_Win", "Window", "window",
                            w.name, "", "autocalculate", "", 1, 4, *v))
                    shade = cfg.shading
                    if shade is not None and shade.overhang_depth_ratio > 0:
                        add(obj("Shading:Overhang:Projection", f"{w.name}_Overhang",
                                f"{w.name}_Win", shade.overhang_offset, 90, 0, 0,
                                shade.overhang_depth_ratio))
                    if shade is not None and shade.fin_depth > 0:
                        add(obj("Shading:Fin", f"{w.name}_Fins", f"{w.name}_Win",
                                0, 0, 0, 90, shade.fin_depth, 0, 0, 0, 90, shade.fin_depth))
        kind = cfg.kinds[room.kind]
        scale = effects.gain_scale(room.zone)
        area = room.floor_area
        if kind.people_per_m2 > 0:
            add(obj("People", f"{rname} People", rname, f"sch:occ:{rname}", "People/Area", "",
                    kind.people_per_m2 * scale, "", 0.3, "autocalculate", "Activity"))
        raf = cfg.plenum.lights_return_fraction if cfg.plenum is not None else 0.0
        add(obj("Lights", f"{rname} Lights", rname, f"sch:lights:{rname}", "Watts/Area", "",
                kind.lights_w_m2 * scale, "", raf, 0.42, 0.18, 1.0))
        add(obj("ElectricEquipment", f"{rname} Equipment", rname, f"sch:equip:{rname}",
                "Watts/Area", "", kind.equipment_w_m2 * scale, "", 0.0, 0.3, 0.0))
        mass_area = cfg.furniture_area_per_floor_area * area * effects.mass_scale(room.zone)
        if mass_area > 0:  # EnergyPlus rejects an internal mass of zero area
            add(obj("InternalMass", f"{rname} Furniture", "furniture", rname, "", mass_area))
        if any(w.neighbour is None for w in walls[rname].walls) and effects.infiltration > 0:
            # per m2 of exterior wall: a roof does not add to it (same as ExteriorArea below it)
            add(obj("ZoneInfiltration:DesignFlowRate", f"{rname} Infiltration", rname, "AlwaysOn",
                    "Flow/ExteriorWallArea" if cfg.floor_position == "top" else "Flow/ExteriorArea", "", "", cfg.infiltration_m3s_per_m2_facade
                    * effects.infiltration, "", 1.0, 0.0, 0.0, 0.0))
        perimeter = any(w.neighbour is None for w in walls[rname].walls)
        flow = area * (cfg.hvac.design_airflow_perimeter if perimeter
                       else cfg.hvac.design_airflow_core)
        add(obj("HVACTemplate:Zone:VAV", rname, "AHU", "Thermostat", flow, "", "", "Scheduled",
                "", "", f"sch:minflow:{rname}", "Flow/Person", 0.00944, "", "", "Electric",
                "AlwaysOn" if effects.reheat else "AlwaysOff", "Reverse", "", "", 35.0))
    if cfg.plenum is not None:
        _plenum(cfg, walls, add)
    # air exchanged both ways with neighbours of other zones (effect switch mixing.ZONE)
    pairs: dict[tuple[str, str], float] = {}
    for rname, room in cfg.rooms.items():
        flow = effects.mixing.get(room.zone, 0.0)
        for w in walls[rname].walls:
            n = w.neighbour
            if flow > 0 and n is not None and cfg.rooms[n].zone != room.zone:
                key = tuple(sorted((rname, n)))
                pairs[key] = max(pairs.get(key, 0.0), flow)
    for (a, b), flow in sorted(pairs.items()):
        add(obj("ZoneCrossMixing", f"{a} {b} Mixing", a, "AlwaysOn", "Flow/Zone", flow, "", "",
                "", b, 0.0))
    add(obj("HVACTemplate:Thermostat", "Thermostat", "sch:htg", "", "sch:clg", ""))
    add(obj("HVACTemplate:System:VAV", "AHU", "AlwaysOn", "autosize", "autosize", 0.7, 1000.0,
            0.9, 1.0, "ChilledWater", "AlwaysOn", "", cfg.hvac.supply_setpoint, "Electric",
            "AlwaysOn", "", 10.0, "", "", "None", "", "", "", "", "", "autosize", "autosize",
            "ProportionalMinimum", "", "DifferentialDryBulb", "NoLockout", 19.0, "", "", "",
            "", "Plenum" if cfg.plenum is not None else "", "DrawThrough", "InletVaneDampers", "StayOff", "", "None", "", "",
            "OutdoorAirTemperatureReset", "None", "None"))
    add(obj("HVACTemplate:Plant:ChilledWaterLoop", "Chilled Water Loop", "", "Intermittent",
            "Default", "", "", 7.22, "ConstantPrimaryNoSecondary"))
    add(obj("HVACTemplate:Plant:Chiller", "District Chilled Water", "DistrictChilledWater",
            "autosize", 3.2, "AirCooled", 1))
    add(obj("Output:SQLite", "SimpleAndTabular"))
    add(obj("Output:Diagnostics", "DisplayExtraWarnings"))
    for key, var in OUTPUT_VARIABLES:
        add(obj("Output:Variable", key, var, "Timestep"))
    for room in cfg.rooms:
        for i, _, _ in room_boxes(cfg, room):
            add(obj("Output:Variable", supply_node(room, i), "System Node Mass Flow Rate",
                    "Timestep"))
            add(obj("Output:Variable", supply_node(room, i), "System Node Temperature",
                    "Timestep"))
    add(obj("Output:Variable", ahu_outlet_node(), "System Node Temperature", "Timestep"))
    return "\n".join(out)


def _plenum(cfg: BuildingConfig, walls, add) -> None:
    """The return plenum zone over the rooms: its floor is each room's ceiling (tile), its
    top the slab (adiabatic) or the roof, its outer walls the facade above the rooms."""
    H, hp = cfg.floor_to_ceiling, cfg.plenum.height
    top = H + hp
    add(obj("Zone", "Plenum", 0.0, 0.0, 0.0, 0.0, 1, 1, hp, "autocalculate", "autocalculate",
            "", "", "No"))
    roof = cfg.floor_position == "top"
    for rname, room in cfg.rooms.items():
        x0, y0, x1, y1 = room.rect
        add(obj("BuildingSurface:Detailed", f"Plenum_Floor_{rname}", "Floor", "plenum_tile",
                "Plenum", "", "Surface", f"{rname}_Ceiling", "NoSun", "NoWind", "", 4,
                x0, y1, H, x1, y1, H, x1, y0, H, x0, y0, H))
        add(obj("BuildingSurface:Detailed", f"Plenum_Top_{rname}", "Roof" if roof else "Ceiling",
                "plenum_deck", "Plenum", "", "Outdoors" if roof else "Adiabatic", "",
                "SunExposed" if roof else "NoSun", "WindExposed" if roof else "NoWind", "", 4,
                x0, y0, top, x1, y0, top, x1, y1, top, x0, y1, top))
        for w in walls[rname].walls:
            if w.neighbour is None:
                v = [c for p in wall_vertices(w, H, top) for c in p]
                add(obj("BuildingSurface:Detailed", f"Plenum_{w.name}", "Wall", "exterior_wall",
                        "Plenum", "", "Outdoors", "", "SunExposed", "WindExposed", "", 4, *v))
