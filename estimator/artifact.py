"""The identified-model artefact: parameters, weekly internal-gains profile, filter noise,
modelling options and the model's structure matrices.

A model file is a JSON document and, beside it, an ``.npz`` of the RC structure (paper
eq:ct_model, affine in the parameters: A0, A_p, Bv0, Bv_p, B_IG, C, capacities, the
box-room map and the state labels), so that serving and forecasting need neither the
EnergyPlus file nor EnergyPlus itself::

    {"schema_version": 2,
     "site": "site.yaml",                      # relative to the JSON file (or absolute)
     "structure": "model.npz",                 # relative to the JSON file; schema 2
     "structure_sha256": "...",                # of the .npz bytes; checked when loading
     "parameters": {"gamma_EW": 25.0, ...},    # optional; missing names -> start values
     "weekly_profile": {"zones": ["NW", ...],  # optional; null -> zeros
                        "values": [[...], ...],    # 672 rows x n_zones [W/m2]
                        "counts": [[...], ...]},   # optional: weeks behind each value
                                                   # (0: filled, forecast.fill_profile)
     "noise": {"sigma_air": 0.3, ...} | null,  # optional filter noise [K]
     "model_options": {"window_solar": "surfaces", "floor_share": 0.25,
                       "roof_solar": "mean"}}
                                               # modelling choices (ModelOptions); a file
                                               # without them was written before they
                                               # existed: window solar on the room air

Schema 1 files (no ``structure``) still load: the structure is then rebuilt from the
site's EnergyPlus file, which needs EnergyPlus (about a second for a floor of rooms).

Everything that is wrong raises :class:`ModelFileError` (a ``ValueError``) with a
message naming the field.
"""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import scipy.sparse as sp
from zonecast.estimator.constants import (
    SIGMA_AIR_ONLINE,
    SIGMA_MEAS,
    SIGMA_WALL_FORECAST,
    STEP,
    STEPS_PER_WEEK,
)
from zonecast.estimator.gains import WeeklyProfile
from zonecast.estimator.idf import read_building
from zonecast.estimator.model import BilinearModel, build_model
from zonecast.estimator.rc.network import (
    DISTURBANCES,
    ModelDefinitionError,
    ModelOptions,
    RCStructure,
    StateLabel,
)
from zonecast.estimator.rc.parameters import ParameterSet
from zonecast.estimator.site import Site, load_site

__all__ = ["ModelBundle", "ModelFileError", "NoiseSettings", "load_model_file",
           "load_structure", "save_structure", "write_model_file"]

SCHEMA_VERSION = 2
#: schema versions this module reads (1: no structure file, rebuilt from the IDF)
READABLE_SCHEMAS = (1, 2)
#: format of the structure .npz
STRUCTURE_FORMAT = 1
_NOISE_KEYS = ("sigma_air", "sigma_wall", "sigma_meas", "p0_sigma_air", "p0_sigma_wall")


class ModelFileError(ValueError):
    """The identified-model file cannot be used; the message says what to fix."""


@dataclass(frozen=True)
class NoiseSettings:
    """Kalman-filter noise of the online runner (standard deviations per 15-min step).

    Attributes
    ----------
    sigma_air, sigma_wall : float
        Process noise of room-air and element states [K]. The air default 0.3 K (not
        the estimator's forecasting default 0.1 K) lets the air states follow the
        measurements, which keeps the per-step f_IG estimate unbiased
        (docs/numerics.md, "Pitfall, measured").
    sigma_meas : float
        Measurement noise of a zone temperature [K].
    p0_sigma_air, p0_sigma_wall : float
        Initial standard deviations of air and element states [K].
    """

    sigma_air: float = SIGMA_AIR_ONLINE
    sigma_wall: float = SIGMA_WALL_FORECAST
    sigma_meas: float = SIGMA_MEAS
    p0_sigma_air: float = 0.3
    p0_sigma_wall: float = 2.0


@dataclass
class ModelBundle:
    """A building's site description, its model with identified parameters, the weekly
    internal-gains profile and the filter noise.

    Attributes
    ----------
    building : str
        Identifier (the site's ``building``).
    site : Site
    model : BilinearModel
    profile : WeeklyProfile
        Fixed internal-gains function [W/m2] on the local time-of-week axis.
    noise : NoiseSettings
    version : str
        ``sha256:`` + first 16 hex digits of the model file's bytes.
    path : Path
        The model file.
    room_volume : dict
        Room -> air volume [m3], to weight several sensors of a zone like C.
    state_zone : ndarray of int
        Zone index of every state (-1: no single zone), for the initial state.
    notes : list of str
        What was defaulted (missing parameters, missing profile).
    site_path : Path, optional
        The site description the model file refers to.
    """

    building: str
    site: Site
    model: BilinearModel
    profile: WeeklyProfile
    noise: NoiseSettings
    version: str
    path: Path
    room_volume: dict[str, float]
    state_zone: np.ndarray
    notes: list[str] = field(default_factory=list)
    site_path: Path | None = None

    @property
    def zones(self) -> list[str]:
        return list(self.site.zones)


def _read_json(path: Path) -> tuple[dict, bytes]:
    if not path.is_file():
        raise ModelFileError(f"model file {path} not found")
    raw = path.read_bytes()
    try:
        doc = json.loads(raw)
    except ValueError as exc:
        raise ModelFileError(f"model file {path} is not valid JSON: {exc}") from None
    if not isinstance(doc, dict):
        raise ModelFileError(f"model file {path} must hold a JSON object, got "
                             f"{type(doc).__name__}")
    version = doc.get("schema_version")
    if version not in READABLE_SCHEMAS:
        raise ModelFileError(f"model file {path}: schema_version must be one of "
                             f"{list(READABLE_SCHEMAS)}, got {version!r}")
    return doc, raw


def _parameters(doc: dict, zones: list[str], path: Path, notes: list[str],
                extra: tuple[str, ...] = ()):
    params = ParameterSet(zones, extra=extra)
    given = doc.get("parameters") or {}
    if not isinstance(given, dict):
        raise ModelFileError(f"{path}: 'parameters' must be an object name -> value")
    bad = {k: v for k, v in given.items()
           if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v)}
    if bad:
        raise ModelFileError(f"{path}: parameters must be finite numbers; bad: {bad}")
    try:
        params = params.update(given) if given else params
    except (ValueError, KeyError) as exc:
        raise ModelFileError(f"{path}: parameters: {exc}") from None
    missing = [n for n in params.param_names if n.lower() not in {k.lower() for k in given}]
    if missing:
        notes.append(f"parameters at start values: {', '.join(missing)}")
    return params


def _profile(doc: dict, zones: list[str], timezone: str, path: Path, notes: list[str]):
    n_bins = STEPS_PER_WEEK
    wp = doc.get("weekly_profile")
    if wp is None:
        notes.append("no weekly internal-gains profile: zeros")
        return WeeklyProfile(np.zeros((n_bins, len(zones))),
                             np.zeros((n_bins, len(zones)), dtype=int), timezone)
    if not isinstance(wp, dict) or "values" not in wp:
        raise ModelFileError(f"{path}: 'weekly_profile' must be null or "
                             '{"zones": [...], "values": [[...]]}')
    names = wp.get("zones", zones)
    if sorted(names) != sorted(zones):
        raise ModelFileError(f"{path}: weekly_profile.zones {names} differ from the site's "
                             f"zones {zones}")
    try:
        values = np.asarray(wp["values"], dtype=float)
    except (TypeError, ValueError):
        raise ModelFileError(f"{path}: weekly_profile.values must be a list of number rows") \
            from None
    if values.shape != (n_bins, len(zones)):
        raise ModelFileError(f"{path}: weekly_profile.values has shape {values.shape}; "
                             f"expected ({n_bins}, {len(zones)}): 672 15-min bins from Monday "
                             "00:00 local time, one column per zone [W/m2]")
    values = values[:, [names.index(z) for z in zones]]
    nan = int(np.isnan(values).sum())
    if nan:
        notes.append(f"weekly profile: {nan} empty bins count as 0")
    counts = np.isfinite(values).astype(int)
    if wp.get("counts") is not None:  # the weeks behind each value (0: a filled bin)
        try:
            given = np.asarray(wp["counts"], dtype=float)
        except (TypeError, ValueError):
            raise ModelFileError(f"{path}: weekly_profile.counts must be a list of number "
                                 "rows") from None
        if given.shape != values.shape or not np.isfinite(given).all() or (given < 0).any() \
                or (given != np.round(given)).any():
            raise ModelFileError(f"{path}: weekly_profile.counts must be whole numbers >= 0 "
                                 f"of the values' shape ({n_bins}, {len(zones)}); got shape "
                                 f"{given.shape}")
        counts = np.where(np.isfinite(values), given[:, [names.index(z) for z in zones]],
                          0).astype(int)
    return WeeklyProfile(values, counts, timezone)


def _reheat_scale(doc: dict, path: Path, boxes: Sequence[str]) -> np.ndarray | None:
    """Per box of the structure, the factor on its measured reheat heat (the model file's
    ``reheat_scale``: box id -> factor, from :meth:`Pipeline.fit_reheat_leak
    <zonecast.estimator.pipeline.Pipeline.fit_reheat_leak>`; a box it does not name, and
    every box of a file without it, takes 1)."""
    raw = doc.get("reheat_scale")
    if raw is None:
        return None
    if not isinstance(raw, dict):
        raise ModelFileError(f"{path}: 'reheat_scale' must be null or an object "
                             "(box id -> factor)")
    unknown = sorted(set(raw) - set(boxes))
    if unknown:
        raise ModelFileError(f"{path}: reheat_scale names boxes the model does not have: "
                             f"{unknown}")
    out = np.ones(len(boxes))
    for i, b in enumerate(boxes):
        if b in raw:
            v = raw[b]
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not 0 <= v < 10:
                raise ModelFileError(f"{path}: reheat_scale[{b!r}] must be a number in "
                                     f"[0, 10), got {v!r}")
            out[i] = float(v)
    return out


def _reheat_from_faces(doc: dict, path: Path) -> bool:
    raw = doc.get("reheat_from_faces", False)
    if not isinstance(raw, bool):
        raise ModelFileError(f"{path}: 'reheat_from_faces' must be true or false, got {raw!r}")
    return raw


def _noise(doc: dict, path: Path) -> NoiseSettings:
    raw = doc.get("noise") or {}
    if not isinstance(raw, dict):
        raise ModelFileError(f"{path}: 'noise' must be null or an object")
    known = {k: raw[k] for k in _NOISE_KEYS if k in raw}
    unknown = sorted(set(raw) - set(_NOISE_KEYS))
    if unknown:
        raise ModelFileError(f"{path}: unknown noise keys {unknown}; known: {list(_NOISE_KEYS)}")
    for k, v in known.items():
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not v > 0:
            raise ModelFileError(f"{path}: noise.{k} must be a positive number [K], got {v!r}")
    return NoiseSettings(**{k: float(v) for k, v in known.items()})


_OPTION_KEYS = ("window_solar", "floor_share", "roof_solar", "infiltration", "facades", "ground",
                "shading", "return_air", "sky", "interior_radiation", "internal_gains",
                "window_angle", "roof_exterior", "envelope_radiation", "solar_enclosure",
                "adiabatic", "layers", "internal_mass", "inside_convection", "roof_inside")
#: what a model file without an option was built with (options added later)
_LEGACY_DEFAULTS = {"infiltration": "none", "facades": "cardinal", "ground": "adiabatic",
                    "shading": "none", "return_air": "none", "roof_solar": "mean",
                    "sky": "none", "interior_radiation": "none", "internal_gains": "air",
                    "window_angle": "none", "roof_exterior": "fitted",
                    "envelope_radiation": "none", "solar_enclosure": "room",
                    "adiabatic": "zero_flux", "layers": "lumped",
                    "internal_mass": "both_faces", "inside_convection": "constant",
                    "roof_inside": "fitted"}
#: what a model file without ``model_options`` was built with (files written before the
#: key existed put window solar on the room air, the paper's placement)
LEGACY_OPTIONS = {"window_solar": "air"}


def _model_options(doc: dict, path: Path, notes: list[str]):
    raw = doc.get("model_options")
    if raw is None:
        notes.append("no model_options: window solar on the room air (files written before "
                     "model_options existed)")
        raw = LEGACY_OPTIONS
    if not isinstance(raw, dict):
        raise ModelFileError(f"{path}: 'model_options' must be an object, e.g. "
                             '{"window_solar": "floor"}')
    unknown = sorted(set(raw) - set(_OPTION_KEYS))
    if unknown:
        raise ModelFileError(f"{path}: unknown model_options {unknown}; known: "
                             f"{list(_OPTION_KEYS)}")
    # files written before an option existed were built without it
    raw = {**_LEGACY_DEFAULTS, **raw}
    try:
        return ModelOptions(**raw)
    except ModelDefinitionError as exc:
        raise ModelFileError(f"{path}: model_options: {exc}") from None


def model_options_dict(options) -> dict:
    """The ``model_options`` entry of a model file for :class:`ModelOptions` ``options``."""
    return {k: getattr(options, k) for k in _OPTION_KEYS}


def load_model_file(path: str | Path) -> ModelBundle:
    """Read an identified-model file and build the model.

    Parameters
    ----------
    path : path
        The JSON file (format in the module docstring).

    Returns
    -------
    ModelBundle

    Raises
    ------
    ModelFileError
        Missing file, bad JSON, wrong schema version, unknown parameter, profile of the
        wrong shape, or a site/IDF that cannot be read (its message is included).
    """
    path = Path(path)
    doc, raw = _read_json(path)
    site_ref = doc.get("site")
    if not isinstance(site_ref, str) or not site_ref:
        raise ModelFileError(f"{path}: 'site' must be the path of the site.yaml, relative to "
                             "the model file")
    site_path = (path.parent / site_ref).resolve()
    try:
        site = load_site(site_path)
    except FileNotFoundError:
        raise ModelFileError(f"{path}: site description {site_path} not found") from None
    except ValueError as exc:
        raise ModelFileError(f"{path}: site description {site_ref}: {exc}") from None
    if site.step != STEP:
        raise ModelFileError(f"{path}: the service runs on a 15-min step; the site has "
                             f"{site.step}")
    notes: list[str] = []
    zones = list(site.zones)
    profile = _profile(doc, zones, site.timezone, path, notes)
    noise = _noise(doc, path)
    options = _model_options(doc, path, notes)
    if doc.get("structure") is not None:
        structure, volume = _stored_structure(doc, path, site, options)
        params = _parameters(doc, zones, path, notes, structure.extra_params)
        model = BilinearModel(structure, params,
                              reheat_scale=_reheat_scale(doc, path, structure.boxes),
                              reheat_from_faces=_reheat_from_faces(doc, path))
    else:
        notes.append("no structure file: model rebuilt from the site's EnergyPlus file")
        try:
            building = read_building(site.idf_path, weather_file=site.weather_path)
        except (ValueError, FileNotFoundError) as exc:
            raise ModelFileError(f"{path}: building {site.idf_path}: {exc}") from None
        model = build_model(building, site.zones,
                            {b: box.room for b, box in site.boxes.items()}, options=options)
        params = _parameters(doc, zones, path, notes, model.structure.extra_params)
        model = BilinearModel(model.structure, params,
                              reheat_scale=_reheat_scale(doc, path, model.structure.boxes),
                              reheat_from_faces=_reheat_from_faces(doc, path))
        volume = {name: z.volume for name, z in building.zones.items()}
    return ModelBundle(
        building=site.building, site=site, model=model, profile=profile, noise=noise,
        version="sha256:" + hashlib.sha256(raw).hexdigest()[:16], path=path,
        room_volume=volume, state_zone=model.structure.state_zones(), notes=notes,
        site_path=site_path)


def _stored_structure(doc: dict, path: Path, site: Site,
                      options: ModelOptions) -> tuple[RCStructure, dict[str, float]]:
    """The structure file a model file names, checked against the file and the site."""
    ref = doc["structure"]
    if not isinstance(ref, str) or not ref:
        raise ModelFileError(f"{path}: 'structure' must be the path of the structure .npz, "
                             "relative to the model file")
    npz = (path.parent / ref).resolve()
    if not npz.is_file():
        raise ModelFileError(f"{path}: structure file {npz} not found; copy it beside the "
                             "model file or write the model again with zonecast identify")
    want = doc.get("structure_sha256")
    if want is not None and hashlib.sha256(npz.read_bytes()).hexdigest() != want:
        raise ModelFileError(f"{path}: structure file {npz} does not match structure_sha256 "
                             "(it was replaced after the model file was written)")
    try:
        structure, volume = load_structure(npz)
    except (ValueError, KeyError, OSError) as exc:
        raise ModelFileError(f"{path}: structure file {npz}: {exc}") from None
    if list(structure.zones) != list(site.zones):
        raise ModelFileError(f"{path}: the structure's zones {list(structure.zones)} differ "
                             f"from the site's {list(site.zones)}")
    if structure.hvac_boxes != list(site.boxes):
        raise ModelFileError(f"{path}: the structure's boxes {structure.hvac_boxes} differ "
                             f"from the site's {list(site.boxes)}")
    if structure.options != options:
        raise ModelFileError(f"{path}: model_options {options} differ from the options the "
                             f"structure was built with {structure.options}")
    return structure, volume


# --------------------------------------------------------------------------- structure file
def _csr_arrays(name: str, m: sp.csr_matrix, out: dict[str, np.ndarray]) -> None:
    m = sp.csr_matrix(m)
    out[f"{name}.data"], out[f"{name}.indices"] = m.data, m.indices
    out[f"{name}.indptr"], out[f"{name}.shape"] = m.indptr, np.array(m.shape)


def _csr(name: str, z) -> sp.csr_matrix:
    return sp.csr_matrix((z[f"{name}.data"], z[f"{name}.indices"], z[f"{name}.indptr"]),
                         shape=tuple(int(s) for s in z[f"{name}.shape"]))


def _disturbance_columns(m: sp.csr_matrix) -> sp.csr_matrix:
    """A B_v block with a column per :data:`~.rc.network.DISTURBANCES`: files written
    before the roofs' horizontal column ``solH`` have one fewer, which no element used."""
    if m.shape[1] == len(DISTURBANCES) - 1:
        m = sp.csr_matrix((m.data, m.indices, m.indptr), shape=(m.shape[0], len(DISTURBANCES)))
    if m.shape[1] != len(DISTURBANCES):
        raise ValueError(f"structure B_v has {m.shape[1]} columns; this version reads "
                         f"{len(DISTURBANCES)} ({', '.join(DISTURBANCES)})")
    return m


def save_structure(path: str | Path, structure: RCStructure,
                   room_volume: dict[str, float]) -> Path:
    """Write an RC structure and the rooms' air volumes to ``path`` (.npz, no pickles).

    The arrays are stored bit for bit, so a model rebuilt with :func:`load_structure`
    steps exactly like the one built from the EnergyPlus file.

    Parameters
    ----------
    path : path
    structure : RCStructure
    room_volume : dict
        Room -> air volume [m3] (weights of several sensors of one zone).
    """
    arrays: dict[str, np.ndarray] = {
        "capacity": structure.capacity, "B_ig": structure.B_ig, "C": structure.C,
        "room_of_box": structure.room_of_box,
    }
    if structure.return_of_box is not None:  # only when there are any
        arrays["return_of_box"] = np.asarray(structure.return_of_box, dtype=int)
    _csr_arrays("A0", structure.A0, arrays)
    _csr_arrays("Bv0", structure.Bv0, arrays)
    for i, m in enumerate(structure.A_p):
        _csr_arrays(f"A_p{i}", m, arrays)
    for i, m in enumerate(structure.Bv_p):
        _csr_arrays(f"Bv_p{i}", m, arrays)
    for room, w in structure.window_area.items():
        arrays[f"window_area.{room}"] = np.asarray(w, dtype=float)
    meta = {"format": STRUCTURE_FORMAT,
            "labels": [[lab.kind, lab.room, lab.element, lab.layer] for lab in structure.labels],
            "rooms": structure.rooms, "zones": structure.zones, "boxes": structure.boxes,
            "cp_air": structure.cp_air, "notes": structure.notes, "areas": structure.areas,
            "window_rooms": list(structure.window_area), "n_A_p": len(structure.A_p),
            "n_Bv_p": len(structure.Bv_p), "options": asdict(structure.options),
            "extra_params": list(structure.extra_params),
            "facade_rotation": structure.facade_rotation,
            "room_volume": {k: float(v) for k, v in room_volume.items()}}
    if structure.scheduled:  # written only when there are any (older files stay the same)
        meta["scheduled"] = structure.scheduled
    if structure.shading:  # likewise
        meta["shading"] = structure.shading
    if structure.window_panes:  # likewise
        meta["window_panes"] = int(structure.window_panes)
    if structure.switched:  # likewise
        sw = structure.switched
        meta["switched_rooms"] = list(sw["rooms"])
        arrays["switched.links"] = np.asarray(sw["links"], dtype=np.int64)
        arrays["switched.area"] = np.asarray(sw["area"], dtype=float)
        arrays["switched.param"] = np.asarray(sw["param"], dtype=np.int64)
        arrays["switched.factor"] = np.asarray(sw["factor"], dtype=float)
    path = Path(path)
    with path.open("wb") as fh:
        np.savez(fh, meta=np.array(json.dumps(meta)), **arrays)
    return path


def load_structure(path: str | Path) -> tuple[RCStructure, dict[str, float]]:
    """Read a structure file written by :func:`save_structure`.

    Returns
    -------
    structure : RCStructure
    room_volume : dict
        Room -> air volume [m3].
    """
    with np.load(path, allow_pickle=False) as z:
        meta = json.loads(str(z["meta"]))
        if meta.get("format") != STRUCTURE_FORMAT:
            raise ValueError(f"structure format {meta.get('format')!r}; this version reads "
                             f"{STRUCTURE_FORMAT}")
        structure = RCStructure(
            labels=[StateLabel(*lab) for lab in meta["labels"]],
            rooms=list(meta["rooms"]), zones={k: list(v) for k, v in meta["zones"].items()},
            boxes=dict(meta["boxes"]), capacity=z["capacity"],
            A0=_csr("A0", z), A_p=[_csr(f"A_p{i}", z) for i in range(meta["n_A_p"])],
            Bv0=_disturbance_columns(_csr("Bv0", z)),
            Bv_p=[_disturbance_columns(_csr(f"Bv_p{i}", z)) for i in range(meta["n_Bv_p"])],
            B_ig=z["B_ig"], room_of_box=z["room_of_box"], C=z["C"], cp_air=meta["cp_air"],
            notes=list(meta["notes"]), areas=dict(meta["areas"]),
            window_area={r: z[f"window_area.{r}"] for r in meta["window_rooms"]},
            options=ModelOptions(**{**_LEGACY_DEFAULTS, **meta["options"]}),
            facade_rotation=float(meta.get("facade_rotation", 0.0)),
            scheduled=dict(meta.get("scheduled", {})),
            shading=list(meta.get("shading", [])),
            return_of_box=z["return_of_box"] if "return_of_box" in z.files else None,
            window_panes=int(meta.get("window_panes", 0)),
            switched=({"links": z["switched.links"], "area": z["switched.area"],
                       "param": z["switched.param"], "factor": z["switched.factor"],
                       "rooms": list(meta["switched_rooms"])}
                      if "switched_rooms" in meta else {}),
            extra_params=tuple(meta.get("extra_params", ())))
    return structure, {k: float(v) for k, v in meta["room_volume"].items()}


def write_model_file(path: str | Path, site: str | Path, *,
                     parameters: dict[str, float] | None = None,
                     weekly_profile: dict | None = None,
                     noise: dict[str, float] | None = None,
                     model_options: dict[str, str | float] | None = None,
                     structure: RCStructure | None = None,
                     room_volume: dict[str, float] | None = None,
                     extra: dict[str, Any] | None = None) -> Path:
    """Write a model file pointing to ``site`` (stored relative to the file when both are
    on one drive, else absolute).

    Used by ``zonecast identify`` and ``zonecast reproduce``, by tests, and for sites
    without identification. ``model_options`` are the :class:`ModelOptions` the model was
    built with (default: the structure's, else the current defaults). With ``structure``
    (and the rooms' ``room_volume`` [m3]) the structure goes to the same name with
    ``.npz`` and loading needs no EnergyPlus. ``extra`` adds informational keys (e.g.
    ``identification``).
    """
    path = Path(path)
    site = Path(site).resolve()
    try:
        ref = os.path.relpath(site, path.parent.resolve())
    except ValueError:  # another drive (Windows)
        ref = str(site)
    if model_options is None:
        model_options = model_options_dict(structure.options if structure is not None
                                           else ModelOptions())
    doc: dict[str, Any] = {"schema_version": SCHEMA_VERSION, "site": ref}
    if structure is not None:
        if room_volume is None:
            raise ValueError("write_model_file: give room_volume (room -> air volume [m3]) "
                             "with the structure")
        npz = save_structure(path.with_suffix(".npz"), structure, room_volume)
        doc["structure"] = npz.name
        doc["structure_sha256"] = hashlib.sha256(npz.read_bytes()).hexdigest()
    doc.update({"parameters": parameters or {}, "weekly_profile": weekly_profile,
                "noise": noise, "model_options": model_options, **(extra or {})})
    path.write_text(json.dumps(doc, indent=1))
    return path
