"""Read an identified-model file (the output of ``zonecast identify``) into a ready model.

File format (JSON, ``schema_version`` 1)::

    {"schema_version": 1,
     "site": "site.yaml",                      # relative to the JSON file (or absolute)
     "parameters": {"gamma_EW": 25.0, ...},    # optional; missing names -> start values
     "weekly_profile": {"zones": ["NW", ...],  # optional; null -> zeros
                        "values": [[...], ...]},   # 672 rows x n_zones [W/m2]
     "noise": {"sigma_air": 0.3, ...} | null,  # optional filter noise [K]
     "model_options": {"window_solar": "surfaces", "floor_share": 0.25,
                       "roof_solar": "mean"}}
                                               # modelling choices (ModelOptions); a file
                                               # without them was written before they
                                               # existed: window solar on the room air

Everything that is wrong raises :class:`ModelFileError` (a ``ValueError``) with a
message naming the field. Loading reads the site description and its EnergyPlus
file and builds the bilinear model (about a second for a floor of rooms).
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

__all__ = ["ModelBundle", "ModelFileError", "NoiseSettings", "load_model_file",
           "write_model_file"]

SCHEMA_VERSION = 1
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

    sigma_air: float = 0.3
    sigma_wall: float = 0.01
    sigma_meas: float = 0.2
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
    """

    building: str
    site: Any
    model: Any
    profile: Any
    noise: NoiseSettings
    version: str
    path: Path
    room_volume: dict[str, float]
    state_zone: np.ndarray
    notes: list[str] = field(default_factory=list)

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
    if version != SCHEMA_VERSION:
        raise ModelFileError(f"model file {path}: schema_version must be {SCHEMA_VERSION}, "
                             f"got {version!r}")
    return doc, raw


def _parameters(doc: dict, zones: list[str], path: Path, notes: list[str]):
    from zonecast.estimator.rc.parameters import ParameterSet

    params = ParameterSet(zones)
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
    from zonecast.estimator.gains import WeeklyProfile

    n_bins = 672
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
    return WeeklyProfile(values, counts, timezone)


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


_OPTION_KEYS = ("window_solar", "floor_share", "roof_solar")
#: what a model file without ``model_options`` was built with (files written before the
#: key existed put window solar on the room air, the paper's placement)
LEGACY_OPTIONS = {"window_solar": "air"}


def _model_options(doc: dict, path: Path, notes: list[str]):
    from zonecast.estimator.rc.network import ModelDefinitionError, ModelOptions

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
    try:
        return ModelOptions(**raw)
    except ModelDefinitionError as exc:
        raise ModelFileError(f"{path}: model_options: {exc}") from None


def model_options_dict(options) -> dict:
    """The ``model_options`` entry of a model file for :class:`ModelOptions` ``options``."""
    return {k: getattr(options, k) for k in _OPTION_KEYS}


def state_zones(structure, zones: list[str]) -> np.ndarray:
    """Zone index of every state: the zone of the room the state belongs to, else -1."""
    room_zone = {r.upper(): i for i, z in enumerate(zones) for r in structure.zones[z]}
    return np.array([room_zone.get(lbl.room.upper(), -1) if lbl.kind != "unmeasured_air"
                     else -1 for lbl in structure.labels], dtype=int)


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
    from zonecast.estimator.idf import read_building
    from zonecast.estimator.model import build_model
    from zonecast.estimator.site import load_site

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
    if site.step != pd.Timedelta("15min"):
        raise ModelFileError(f"{path}: the service runs on a 15-min step; the site has "
                             f"{site.step}")
    notes: list[str] = []
    zones = list(site.zones)
    params = _parameters(doc, zones, path, notes)
    profile = _profile(doc, zones, site.timezone, path, notes)
    noise = _noise(doc, path)
    options = _model_options(doc, path, notes)
    try:
        building = read_building(site.idf_path)
    except (ValueError, FileNotFoundError) as exc:
        raise ModelFileError(f"{path}: building {site.idf_path}: {exc}") from None
    model = build_model(building, site.zones, {b: box.room for b, box in site.boxes.items()},
                        params, options=options)
    volume = {name: z.volume for name, z in building.zones.items()}
    return ModelBundle(
        building=site.building, site=site, model=model, profile=profile, noise=noise,
        version="sha256:" + hashlib.sha256(raw).hexdigest()[:16], path=path,
        room_volume=volume, state_zone=state_zones(model.structure, zones), notes=notes)


def write_model_file(path: str | Path, site: str | Path, *,
                     parameters: dict[str, float] | None = None,
                     weekly_profile: dict | None = None,
                     noise: dict[str, float] | None = None,
                     model_options: dict[str, str | float] | None = None,
                     extra: dict[str, Any] | None = None) -> Path:
    """Write a model file (schema 1) pointing to ``site`` (stored relative to the file
    when both are on one drive, else absolute).

    Used by ``zonecast identify`` and ``zonecast reproduce``, by tests, and for sites
    without identification. ``model_options`` are the :class:`ModelOptions` the model was
    built with (default: the current defaults). ``extra`` adds informational keys (e.g.
    ``identification``).
    """
    import os

    from zonecast.estimator.rc.network import ModelOptions

    path = Path(path)
    site = Path(site).resolve()
    try:
        ref = os.path.relpath(site, path.parent.resolve())
    except ValueError:  # another drive (Windows)
        ref = str(site)
    doc = {"schema_version": SCHEMA_VERSION, "site": ref, "parameters": parameters or {},
           "weekly_profile": weekly_profile, "noise": noise,
           "model_options": model_options or model_options_dict(ModelOptions()),
           **(extra or {})}
    path.write_text(json.dumps(doc, indent=1))
    return path
