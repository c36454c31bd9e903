"""Vertices of EnergyPlus's rectangular ("simple geometry") surfaces.

EnergyPlus lets a building be described without vertices: ``Wall:Exterior``, ``Roof``,
``Floor:GroundContact`` and their kin give a starting corner, an azimuth, a tilt, a length and
a height (or width); ``Window``, ``Door`` and ``GlazedDoor`` give a position and a size in the
plane of their base surface; ``Shading:Site`` and ``Shading:Building`` are rectangles too.
EnergyPlus turns each into four vertices when it reads the input. This module does the same so
that :mod:`zonecast.estimator.idf` can read such files like the detailed ones. The vector
algebra is four lines per surface, so no library is used; the conventions were checked
against the vertices EnergyPlus 25.2 itself writes to ``eplusout.eio``
(``Output:Surfaces:List, DetailsWithVertices``; tests/estimator/test_idf_rectangles.py).

Conventions (EnergyPlus Input Output Reference, "Surface(s) -- Simple Geometry"):

- azimuth [deg] is the outward normal's direction clockwise from (the zone's) north, tilt
  [deg] the angle of the outward normal from straight up (walls 90, roofs 0, floors 180);
- the starting corner is the surface's lower left corner seen from outside; the length runs
  to the right seen from outside, the height (width) up the surface;
- a subsurface's starting x and z are measured from its base surface's lower left corner,
  along the base's length and up the base.

Vertices are returned counter-clockwise seen from outside, starting at the upper left corner,
as EnergyPlus reports them.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["in_plane_axes", "lower_left", "rectangle", "subsurface"]


def in_plane_axes(azimuth: float, tilt: float) -> tuple[np.ndarray, np.ndarray]:
    """Unit vectors along a surface's length (to the right seen from outside) and up its
    height, for outward normal azimuth ``azimuth`` [deg] and tilt ``tilt`` [deg]."""
    a, t = math.radians(azimuth), math.radians(tilt)
    along = np.array([-math.cos(a), math.sin(a), 0.0])
    up = np.array([-math.cos(t) * math.sin(a), -math.cos(t) * math.cos(a), math.sin(t)])
    return along, up


def rectangle(start, azimuth: float, tilt: float, length: float, height: float) -> np.ndarray:
    """(4, 3) vertices [m] of a rectangle whose lower left corner seen from outside is
    ``start`` [m], with ``length`` [m] to the right and ``height`` [m] up the surface."""
    if not (length > 0 and height > 0):
        raise ValueError(f"a rectangular surface needs a positive length and height "
                         f"(got {length} and {height})")
    s = np.asarray(start, dtype=float)
    along, up = in_plane_axes(azimuth, tilt)
    return np.array([s + height * up, s, s + length * along, s + length * along + height * up])


def lower_left(vertices: np.ndarray, along: np.ndarray, up: np.ndarray) -> np.ndarray:
    """The lower left corner seen from outside of a counter-clockwise polygon: the lowest
    vertex up the surface, the leftmost of those."""
    v = np.asarray(vertices, dtype=float)
    h = v @ up
    low = v[h <= h.min() + 1e-6]
    return low[np.argmin(low @ along)]


def subsurface(base: np.ndarray, x: float, z: float, length: float, height: float) -> np.ndarray:
    """(4, 3) vertices [m] of a window or door at ``x``, ``z`` [m] from the lower left corner
    of the base surface whose counter-clockwise world vertices are ``base`` [m].

    On an inclined or vertical base the axes follow from its normal; on a horizontal one
    (a skylight on a flat roof) from its vertices as EnergyPlus stores them: the second
    vertex is the lower left corner, the third along the length, the first up the surface.
    """
    v = np.asarray(base, dtype=float)
    n = 0.5 * np.cross(v, np.roll(v, -1, axis=0)).sum(axis=0)
    n = n / np.linalg.norm(n)
    if math.hypot(n[0], n[1]) > 1e-6:
        tilt = math.degrees(math.acos(max(-1.0, min(1.0, float(n[2])))))
        azimuth = math.degrees(math.atan2(n[0], n[1]))
        along, up = in_plane_axes(azimuth, tilt)
        origin = lower_left(v, along, up)
    else:
        origin = v[1]
        along = (v[2] - v[1]) / np.linalg.norm(v[2] - v[1])
        up = np.cross(n, along)
    s = origin + x * along + z * up
    return np.array([s + height * up, s, s + length * along, s + length * along + height * up])
