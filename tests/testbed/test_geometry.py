import numpy as np
import pytest
from zonecast.testbed.config import load_config
from zonecast.testbed.geometry import SIDES, plan_walls, wall_vertices, window_on


@pytest.fixture(scope="module")
def cfg():
    return load_config("office6")


def newell(vs):
    v = np.asarray(vs, float)
    n = np.zeros(3)
    for a, b in zip(v, np.roll(v, -1, axis=0)):
        n += [(a[1] - b[1]) * (a[2] + b[2]), (a[2] - b[2]) * (a[0] + b[0]),
              (a[0] - b[0]) * (a[1] + b[1])]
    return n


def test_floor_matches_the_paper(cfg):
    assert sum(r.floor_area for r in cfg.rooms.values()) == pytest.approx(1300.0)
    assert list(cfg.zones) == ["NW", "NE", "W", "E", "S", "C"]
    assert len(cfg.rooms) == 21
    assert not any(cfg.rooms[r].windows for r in cfg.zones["NE"])


def test_interior_walls_pair_up_and_exterior_walls_form_the_outline(cfg):
    walls = plan_walls({n: r.rect for n, r in cfg.rooms.items()})
    names = {w.name: w for g in walls.values() for w in g.walls}
    ext = 0.0
    for w in names.values():
        if w.neighbour is None:
            ext += w.length
        else:
            p = names[w.partner]
            assert p.partner == w.name and p.room == w.neighbour
            assert p.length == pytest.approx(w.length)
    assert ext == pytest.approx(2 * (52 + 25))


def test_vertices_face_outwards(cfg):
    walls = plan_walls({n: r.rect for n, r in cfg.rooms.items()})
    for g in walls.values():
        for w in g.walls:
            n = newell(wall_vertices(w, 0.0, 3.0))
            want = np.array([*SIDES[w.side][0], 0.0])
            np.testing.assert_allclose(n / np.linalg.norm(n), want, atol=1e-12)
            assert np.linalg.norm(n) / 2 == pytest.approx(w.length * 3.0)


def test_window_gives_the_ratio_and_stays_inside():
    from zonecast.testbed.geometry import Wall
    w = Wall("x", "r", "S", (0.0, 0.0), (10.0, 0.0))
    u0, u1, z0, z1 = window_on(w, 3.0, 0.4)
    assert (u1 - u0) * (z1 - z0) == pytest.approx(0.4 * 30.0)
    assert 0 < u0 < u1 < 10 and 0 < z0 < z1 < 3
