"""Plan geometry: axis-aligned rectangular rooms -> EnergyPlus surfaces.

Walls between rooms are split where neighbours change so that every interior
wall segment has an exact partner surface in the neighbouring room
(EnergyPlus ``Outside Boundary Condition = Surface``). Segments on the floor's
outline are exterior walls. Floors and ceilings are adiabatic: the floors above
and below are conditioned alike (a middle floor of a multi-storey building).
"""

from __future__ import annotations

from dataclasses import dataclass, field

# outward normals of the four wall sides and their azimuth [deg from north, clockwise]
SIDES = {"S": ((0.0, -1.0), 180.0), "E": ((1.0, 0.0), 90.0),
         "N": ((0.0, 1.0), 0.0), "W": ((-1.0, 0.0), 270.0)}
EPS = 1e-6


@dataclass
class Wall:
    name: str
    room: str
    side: str                      # S, E, N, W (outward normal)
    a: tuple[float, float]         # start point of the segment in plan [m]
    b: tuple[float, float]         # end point [m]
    neighbour: str | None = None   # room on the other side, None = outdoors
    partner: str | None = None     # name of the matching surface in the neighbour
    window: tuple[float, float, float, float] | None = None  # (u0, u1, z0, z1) along the wall

    @property
    def length(self) -> float:
        return abs(self.b[0] - self.a[0]) + abs(self.b[1] - self.a[1])


@dataclass
class RoomGeometry:
    name: str
    rect: tuple[float, float, float, float]
    walls: list[Wall] = field(default_factory=list)


def _side_segment(rect, side):
    x0, y0, x1, y1 = rect
    return {"S": ((x0, y0), (x1, y0)), "N": ((x0, y1), (x1, y1)),
            "W": ((x0, y0), (x0, y1)), "E": ((x1, y0), (x1, y1))}[side]


_OPPOSITE = {"S": "N", "N": "S", "E": "W", "W": "E"}


def plan_walls(rooms: dict[str, tuple[float, float, float, float]]) -> dict[str, RoomGeometry]:
    """Split every room's four sides into segments by neighbour.

    Parameters
    ----------
    rooms : mapping room name -> (x0, y0, x1, y1) [m]

    Returns
    -------
    dict of room name -> RoomGeometry with walls; interior segments carry the
    neighbour and partner surface names.
    """
    out = {n: RoomGeometry(n, r) for n, r in rooms.items()}
    for name, rect in rooms.items():
        for side in ("S", "E", "N", "W"):
            (ax, ay), (bx, by) = _side_segment(rect, side)
            horizontal = side in ("S", "N")
            lo, hi = (ax, bx) if horizontal else (ay, by)
            fixed = ay if horizontal else ax
            cuts = []  # (lo, hi, neighbour)
            for other, orect in rooms.items():
                if other == name:
                    continue
                (oax, oay), (obx, oby) = _side_segment(orect, _OPPOSITE[side])
                ofixed = oay if horizontal else oax
                if abs(ofixed - fixed) > EPS:
                    continue
                olo, ohi = (oax, obx) if horizontal else (oay, oby)
                s, e = max(lo, olo), min(hi, ohi)
                if e - s > EPS:
                    cuts.append((s, e, other))
            cuts.sort()
            pieces, pos = [], lo
            for s, e, other in cuts:
                if s - pos > EPS:
                    pieces.append((pos, s, None))
                pieces.append((s, e, other))
                pos = e
            if hi - pos > EPS:
                pieces.append((pos, hi, None))
            for i, (s, e, other) in enumerate(pieces):
                a = (s, fixed) if horizontal else (fixed, s)
                b = (e, fixed) if horizontal else (fixed, e)
                tag = f"{other}" if other else "Ext"
                wname = f"{name}_Wall{side}_{i}_{tag}"
                out[name].walls.append(Wall(wname, name, side, a, b, other))
    # pair partners: same segment seen from the neighbour
    index = {}
    for g in out.values():
        for w in g.walls:
            if w.neighbour:
                key = (frozenset((w.room, w.neighbour)), tuple(sorted((w.a, w.b))))
                index.setdefault(key, []).append(w)
    for key, ws in index.items():
        if len(ws) != 2:
            raise ValueError(f"interior wall {key} has {len(ws)} sides; rooms overlap or gap")
        ws[0].partner, ws[1].partner = ws[1].name, ws[0].name
    return out


def wall_vertices(w: Wall, z0: float, z1: float, u=None):
    """Vertices (upper-left first, counter-clockwise seen from outside) of a wall or of a
    window sub-rectangle ``u = (u0, u1, zlo, zhi)`` measured along the wall [m]."""
    (nx, ny), _ = SIDES[w.side]
    right = (-ny, nx)  # a viewer outside, facing the wall, has this direction on the right
    pa = w.a[0] * right[0] + w.a[1] * right[1]
    pb = w.b[0] * right[0] + w.b[1] * right[1]
    left, rightp = (w.a, w.b) if pa < pb else (w.b, w.a)
    if u is not None:
        u0, u1, z0, z1 = u
        dx, dy = rightp[0] - left[0], rightp[1] - left[1]
        L = abs(dx) + abs(dy)
        left, rightp = ((left[0] + dx * u0 / L, left[1] + dy * u0 / L),
                        (left[0] + dx * u1 / L, left[1] + dy * u1 / L))
    return [(left[0], left[1], z1), (left[0], left[1], z0),
            (rightp[0], rightp[1], z0), (rightp[0], rightp[1], z1)]


def window_on(w: Wall, height: float, wwr: float, margin: float = 0.3,
              sill: float = 0.8) -> tuple[float, float, float, float] | None:
    """A horizontal strip window giving window-to-wall ratio ``wwr`` on wall ``w``."""
    L = w.length
    if wwr <= 0 or L < 2 * margin + 0.5:
        return None
    width = L - 2 * margin
    h = wwr * L * height / width
    top = min(height - 0.2, sill + h)
    z0 = max(0.1, top - h)
    return (margin, margin + width, z0, top)
