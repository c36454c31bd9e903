"""Exterior shading of windows: overhangs, fins and shading surfaces of an EnergyPlus input.

EnergyPlus shades a window's beam irradiance by the sunlit fraction of its area (the
shadows of shading surfaces projected along the sun's rays and clipped to the window) and
its sky diffuse irradiance by a fixed ratio: the sunlit fraction averaged over the sky
vault, weighted by each direction's contribution to the window's irradiance (Engineering
Reference, "Shading Module" and "Sky Diffuse Solar Radiation"). This module does the same
for the model's solar columns:

* :func:`shade_polygons` turns ``Shading:Overhang``, ``Shading:Overhang:Projection``,
  ``Shading:Fin``, ``Shading:Fin:Projection`` and the detailed shading surfaces
  (zone, building, site) into world polygons per window;
* :func:`sunlit_fraction` projects them onto the window's plane for each sun position and
  clips them with shapely (GEOS), vectorised over time;
* :func:`diffuse_ratios` averages the sunlit fraction over a sampled sky vault: one ratio
  for the isotropic sky and one for the horizon band (Perez's horizon brightening);
* :class:`FacadeShading` turns the four facade columns' components into the window-area
  weighted shaded irradiance of each facade.

The projection, the plane clip of a shading polygon to the window's front half-space and
the sky sampling are a few lines of vector algebra written here (no maintained library
projects 3-D shading polygons onto a plane); the 2-D polygon clipping and union are
shapely's.

Units: lengths [m], angles [deg], irradiance [W/m²]. Coordinates are world coordinates:
x east, y north, z up.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import shapely

__all__ = [
    "FacadeShading",
    "ShadingError",
    "WindowShading",
    "clip_front",
    "diffuse_ratios",
    "fin_polygons",
    "overhang_polygon",
    "sun_vectors",
    "sunlit_fraction",
    "window_frame",
]

#: sky sampling for the diffuse ratios: altitude bands and azimuth steps [deg]
SKY_ALTITUDES = np.arange(3.0, 90.0, 6.0)
SKY_AZIMUTHS = np.arange(2.5, 360.0, 5.0)
#: the horizon band of Perez's model, sampled at these altitudes [deg]
HORIZON_ALTITUDES = np.array([1.0, 3.0, 5.0])


class ShadingError(ValueError):
    """A shading object that cannot be placed (unknown window, degenerate geometry)."""


# --------------------------------------------------------------------------- geometry
def window_frame(vertices: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Origin and axes of a window's plane.

    Parameters
    ----------
    vertices : ndarray, shape (k, 3)
        World coordinates [m], counter-clockwise seen from outside.

    Returns
    -------
    origin, e1, e2, n : ndarray, shape (3,)
        The first vertex; ``e1`` horizontal, to the right seen from outside (``z x n``;
        east for a window facing up); ``e2 = n x e1`` (up the window); ``n`` the outward
        unit normal.
    """
    v = np.asarray(vertices, dtype=float)
    nn = 0.5 * np.cross(v, np.roll(v, -1, axis=0)).sum(axis=0)
    norm = float(np.linalg.norm(nn))
    if norm <= 0.0:
        raise ShadingError("window polygon has no area")
    n = nn / norm
    e1 = np.cross([0.0, 0.0, 1.0], n)
    if np.linalg.norm(e1) < 1e-9:  # horizontal window: e1 east
        e1 = np.array([1.0, 0.0, 0.0])
    e1 = e1 / np.linalg.norm(e1)
    e2 = np.cross(n, e1)
    return v[0].copy(), e1, e2, n


def _plane_coords(points: np.ndarray, origin, e1, e2) -> np.ndarray:
    d = np.asarray(points, dtype=float) - origin
    return np.stack([d @ e1, d @ e2], axis=-1)


def _window_box(vertices, origin, e1, e2) -> tuple[float, float, float, float]:
    uv = _plane_coords(vertices, origin, e1, e2)
    return float(uv[:, 0].min()), float(uv[:, 0].max()), float(uv[:, 1].min()), \
        float(uv[:, 1].max())


def overhang_polygon(vertices: np.ndarray, height_above: float, tilt: float,
                     left_extension: float, right_extension: float,
                     depth: float) -> np.ndarray:
    """World polygon of an overhang above a rectangular window (``Shading:Overhang``).

    Parameters
    ----------
    vertices : window vertices [m], shape (k, 3).
    height_above : distance from the window's top to the overhang [m].
    tilt : angle between the window's plane (upwards) and the overhang [deg]; 90 sticks
        straight out, less tips it up.
    left_extension, right_extension : beyond the window's left and right edges, seen from
        outside [m].
    depth : [m].
    """
    o, e1, e2, n = window_frame(vertices)
    u0, u1, _, w1 = _window_box(vertices, o, e1, e2)
    t = math.radians(tilt)
    out = math.cos(t) * e2 + math.sin(t) * n
    base = o + (w1 + height_above) * e2
    a = base + (u0 - left_extension) * e1
    b = base + (u1 + right_extension) * e1
    return np.array([a, b, b + depth * out, a + depth * out])


def fin_polygons(vertices: np.ndarray, fins: Sequence[Mapping[str, float]]) -> list[np.ndarray]:
    """World polygons of a window's fins (``Shading:Fin``).

    Parameters
    ----------
    vertices : window vertices [m], shape (k, 3).
    fins : up to two mappings with ``side`` (``"left"`` or ``"right"``, seen from
        outside), ``extension`` (from the window's edge [m]), ``above`` and ``below`` (the
        fin's reach above the window's top and below its bottom [m]), ``tilt`` (angle from
        the window's plane, 90 perpendicular [deg]) and ``depth`` [m]; a fin of depth 0 is
        left out.
    """
    o, e1, e2, n = window_frame(vertices)
    u0, u1, w0, w1 = _window_box(vertices, o, e1, e2)
    out = []
    for f in fins:
        if f["depth"] <= 0.0:
            continue
        t = math.radians(f["tilt"])
        if f["side"] == "left":
            u, swing = u0 - f["extension"], -e1
        else:
            u, swing = u1 + f["extension"], e1
        d = math.cos(t) * swing + math.sin(t) * n
        lo = o + u * e1 + (w0 - f["below"]) * e2
        hi = o + u * e1 + (w1 + f["above"]) * e2
        out.append(np.array([lo, hi, hi + f["depth"] * d, lo + f["depth"] * d]))
    return out


def clip_front(polygon: np.ndarray, origin: np.ndarray, normal: np.ndarray,
               eps: float = 1e-6) -> np.ndarray | None:
    """The part of a planar polygon in front of a plane (Sutherland-Hodgman against one
    plane): vertices with ``normal . (p - origin) >= eps`` [m]. ``None`` when nothing is in
    front (a surface behind the window cannot shade it)."""
    p = np.asarray(polygon, dtype=float)
    d = (p - origin) @ normal - eps
    if np.all(d >= 0.0):
        return p
    if np.all(d <= 0.0):
        return None
    out = []
    for i in range(len(p)):
        j = (i + 1) % len(p)
        if d[i] >= 0.0:
            out.append(p[i])
        if (d[i] >= 0.0) != (d[j] >= 0.0):
            s = d[i] / (d[i] - d[j])
            out.append(p[i] + s * (p[j] - p[i]))
    return np.array(out) if len(out) >= 3 else None


def sun_vectors(zenith, azimuth) -> np.ndarray:
    """Unit vectors towards the sun, shape (N, 3), from zenith and azimuth [deg; azimuth
    clockwise from north]."""
    z, a = np.radians(np.asarray(zenith, dtype=float)), np.radians(np.asarray(azimuth,
                                                                                dtype=float))
    return np.stack([np.sin(z) * np.sin(a), np.sin(z) * np.cos(a), np.cos(z)], axis=-1)


# --------------------------------------------------------------------------- one window
@dataclass
class WindowShading:
    """A window and the polygons that can shade it.

    Attributes
    ----------
    name : str
    facade : int
        Solar column of the window's facade (0..3 = E, S, W, N of the building).
    share : float
        The window's share of its facade's exterior window area [-].
    vertices : ndarray, shape (k, 3)
        The window [m].
    shades : list of ndarray (m, 3)
        Shading polygons [m], clipped to the window's front.
    sky, horizon : float
        Diffuse ratios (:func:`diffuse_ratios`) [-]; computed when left as NaN.
    """

    name: str
    facade: int
    share: float
    vertices: np.ndarray
    shades: list[np.ndarray]
    sky: float = math.nan
    horizon: float = math.nan
    _frame: tuple = field(default=None, repr=False, compare=False)
    _polygon: Any = field(default=None, repr=False, compare=False)

    def __post_init__(self):
        self.vertices = np.asarray(self.vertices, dtype=float)
        self._frame = window_frame(self.vertices)
        o, _, _, n = self._frame
        kept = [clip_front(s, o, n) for s in self.shades]
        self.shades = [s for s in kept if s is not None]
        o, e1, e2, _ = self._frame
        self._polygon = shapely.Polygon(_plane_coords(self.vertices, o, e1, e2))
        if not (math.isfinite(self.sky) and math.isfinite(self.horizon)):
            self.sky, self.horizon = diffuse_ratios(self)

    @property
    def area(self) -> float:
        return float(self._polygon.area)

    def to_dict(self) -> dict:
        return {"name": self.name, "facade": self.facade, "share": self.share,
                "vertices": self.vertices.tolist(), "shades": [s.tolist() for s in self.shades],
                "sky": self.sky, "horizon": self.horizon}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> WindowShading:
        return cls(d["name"], int(d["facade"]), float(d["share"]), np.array(d["vertices"]),
                   [np.array(s) for s in d["shades"]], float(d["sky"]), float(d["horizon"]))


def sunlit_fraction(window: WindowShading, sun: np.ndarray) -> np.ndarray:
    """Sunlit fraction of a window's area for each sun direction.

    Parameters
    ----------
    window : WindowShading
    sun : ndarray, shape (N, 3)
        Unit vectors towards the sun (:func:`sun_vectors`).

    Returns
    -------
    ndarray, shape (N,)
        In [0, 1]; 1 where the sun is behind the window's plane (no beam to shade) or
        nothing shades it.
    """
    sun = np.atleast_2d(np.asarray(sun, dtype=float))
    out = np.ones(len(sun))
    o, e1, e2, n = window._frame
    cos_inc = sun @ n
    front = cos_inc > 1e-6
    if not window.shades or not front.any():
        return out
    s = sun[front]
    shadow = None
    for poly in window.shades:
        d = (poly - o) @ n  # (m,) >= 0: in front
        # X = P - s d / (n.s): each vertex along the ray to the sun, onto the plane
        pts = poly[None, :, :] - s[:, None, :] * (d[None, :] / cos_inc[front][:, None])[..., None]
        uv = np.stack([(pts - o) @ e1, (pts - o) @ e2], axis=-1)  # (N', m, 2)
        shapes = shapely.make_valid(shapely.polygons(uv))
        shapes = shapely.intersection(shapes, window._polygon)
        shadow = shapes if shadow is None else shapely.union(shadow, shapes)
    frac = shapely.area(shadow) / window.area
    out[front] = np.clip(1.0 - frac, 0.0, 1.0)
    return out


def _sky_directions(altitudes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    alt, az = np.meshgrid(np.radians(altitudes), np.radians(SKY_AZIMUTHS), indexing="ij")
    alt, az = alt.ravel(), az.ravel()
    vec = np.stack([np.cos(alt) * np.sin(az), np.cos(alt) * np.cos(az), np.sin(alt)], axis=-1)
    return vec, np.cos(alt)  # solid angle of a band cell ~ cos(altitude)


def diffuse_ratios(window: WindowShading) -> tuple[float, float]:
    """Shaded over unshaded sky diffuse irradiance of a window, for an isotropic sky and
    for the horizon band: the sunlit fraction over sampled sky directions weighted by the
    cosine of incidence and each direction's solid angle (as EnergyPlus's
    ``DifShdgRatioIsoSky`` and ``DifShdgRatioHoriz``) [-]."""
    if not window.shades:
        return 1.0, 1.0
    n = window._frame[3]
    ratios = []
    for alts in (SKY_ALTITUDES, HORIZON_ALTITUDES):
        vec, solid = _sky_directions(alts)
        w = np.clip(vec @ n, 0.0, None) * solid
        if w.sum() <= 0.0:
            ratios.append(1.0)
            continue
        f = sunlit_fraction(window, vec)
        ratios.append(float((w * f).sum() / w.sum()))
    return ratios[0], ratios[1]


# --------------------------------------------------------------------------- the facades
@dataclass
class FacadeShading:
    """The shaded windows of a building, applied to the four facade columns.

    A facade column j becomes the window-area weighted irradiance of the facade's windows:
    the unshaded irradiance minus, for each shaded window of share a_w,
    ``a_w [(1 - f_w)(direct + circumsolar) + (1 - R_w) isotropic + (1 - H_w) horizon]``
    with f_w the sunlit fraction, R_w and H_w its diffuse ratios (never below 0: Perez's
    horizon term can be negative, shading never adds light). Ground-reflected irradiance
    is left unshaded (an overhang hides sky, not ground).
    """

    windows: list[WindowShading]

    def __bool__(self) -> bool:
        return any(w.shades for w in self.windows)

    def to_list(self) -> list[dict]:
        return [w.to_dict() for w in self.windows]

    @classmethod
    def from_list(cls, items: Sequence[Mapping[str, Any]] | None) -> FacadeShading:
        return cls([WindowShading.from_dict(d) for d in items or []])

    def sunlit(self, sun: np.ndarray) -> np.ndarray:
        """Sunlit fraction of every window (:func:`sunlit_fraction`), shape (N, windows)."""
        sun = np.atleast_2d(np.asarray(sun, dtype=float))
        out = np.ones((len(sun), len(self.windows)))
        for k, w in enumerate(self.windows):
            if w.shades:
                out[:, k] = sunlit_fraction(w, sun)
        return out

    def loss(self, sun: np.ndarray, direct: np.ndarray, isotropic: np.ndarray,
             circumsolar: np.ndarray, horizon: np.ndarray,
             sunlit: np.ndarray | None = None) -> np.ndarray:
        """Irradiance the shading takes off each facade column [W/m²], shape (N, 4).

        Parameters
        ----------
        sun : (N, 3) unit vectors towards the sun.
        direct, isotropic, circumsolar, horizon : (N, 4) the columns' unshaded components.
        sunlit : (N, windows) the windows' sunlit fractions when already known
            (:meth:`sunlit`; the online runner caches them a day at a time).
        """
        if sunlit is None:
            sunlit = self.sunlit(sun)
        out = np.zeros_like(direct)
        for k, w in enumerate(self.windows):
            if not w.shades:
                continue
            j = w.facade
            f = sunlit[:, k]
            taken = ((1.0 - f) * (direct[:, j] + circumsolar[:, j])
                     + (1.0 - w.sky) * isotropic[:, j] + (1.0 - w.horizon) * horizon[:, j])
            # Perez's horizon term is negative under some skies: shading never adds light
            out[:, j] += w.share * np.maximum(taken, 0.0)
        return out
