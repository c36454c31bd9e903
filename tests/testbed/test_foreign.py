"""Third-party EnergyPlus inputs (NREL's 5ZoneAirCooled and the DOE small office) driven by
the excitation protocol: the patch, the schedules, and one real EnergyPlus week."""

from __future__ import annotations

import datetime as dt
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from zonecast.estimator.idf import load_epjson
from zonecast.estimator.pipeline import Pipeline
from zonecast.estimator.site import load_site
from zonecast.estimator.telemetry import load_telemetry
from zonecast.testbed.foreign import (
    EXPERIMENT_SCHEDULE,
    REPORTING,
    ForeignBuildingError,
    campaign_weeks,
    describe,
    fraction_schedule,
    patch_epjson,
    run_foreign,
    schedule_table,
)
from zonecast.testbed.schedules import plan_blocks

pytestmark = pytest.mark.energyplus

NREL = Path(__file__).resolve().parents[2] / "configs" / "sites" / "nrel"
FIVE_ZONE = NREL / "5ZoneAirCooled.idf"
SMALL_OFFICE = NREL / "RefBldgSmallOfficeNew2004_Chicago.idf"
WEEK = dt.date(2014, 10, 6)        # a campaign week (Monday)
SATURDAY = dt.date(2014, 10, 11)   # its excitation Saturday
PERIODS = [(WEEK - dt.timedelta(days=1), WEEK + dt.timedelta(days=6))]
# object types the patch may replace, change or add; every other object must be untouched
RUN_CONTROL = {"RunPeriod", "SimulationControl", "Timestep", "Version", *REPORTING}
REPORTING_ADDED = {"Output:Variable", "Output:SQLite"}
ADDED = {"Schedule:File", "ScheduleTypeLimits", "EnergyManagementSystem:Sensor",
         "EnergyManagementSystem:Actuator", "EnergyManagementSystem:InternalVariable",
         "EnergyManagementSystem:Program", "EnergyManagementSystem:ProgramCallingManager"}
VAV_KEYS = {"zone_minimum_air_flow_input_method", "minimum_air_flow_fraction_schedule_name"}


@pytest.fixture(scope="module")
def five_zone():
    data, _ = load_epjson(FIVE_ZONE)
    return data


@pytest.fixture(scope="module")
def small_office():
    data, _ = load_epjson(SMALL_OFFICE)
    return data


@pytest.fixture(scope="module")
def week(tmp_path_factory):
    return run_foreign(FIVE_ZONE, tmp_path_factory.mktemp("nrel5"), weeks=[WEEK],
                       excitation_days=[SATURDAY], seed=5)


def _diff(before: dict, after: dict) -> dict[str, set[str]]:
    """Object type -> changed field names, for every object present before."""
    out: dict[str, set[str]] = {}
    for kind, objs in before.items():
        for name, fields in objs.items():
            new = after.get(kind, {}).get(name)
            if new is None:
                out.setdefault(kind, set()).add("<removed>")
                continue
            keys = {k for k in set(fields) | set(new) if fields.get(k) != new.get(k)}
            if keys:
                out.setdefault(kind, set()).update(keys)
    return out


def test_patch_changes_only_the_listed_fields(five_zone):
    layout = describe(five_zone)
    patched, changes = patch_epjson(five_zone, layout, PERIODS)
    diff = _diff(five_zone, patched)
    assert diff.pop("AirTerminal:SingleDuct:VAV:Reheat") == VAV_KEYS
    assert set(diff) <= RUN_CONTROL, diff
    assert "Timestep" not in diff                 # already 4 per hour
    assert next(iter(patched["Version"].values()))["version_identifier"] == "25.2"
    # additions are only the experiment schedules and the EMS program
    assert set(patched) - set(five_zone) <= ADDED | REPORTING_ADDED
    assert all(name.startswith("zonecast") for name in patched["Schedule:File"])
    assert any(c.startswith("AirTerminal:SingleDuct:VAV:Reheat SPACE1-1") for c in changes)
    # the original file is not modified in memory
    t = five_zone["AirTerminal:SingleDuct:VAV:Reheat"]["SPACE1-1 VAV Reheat"]
    assert t["zone_minimum_air_flow_input_method"] == "Constant"


def test_layout_of_the_two_nrel_files(five_zone, small_office):
    five = describe(five_zone)
    assert five.zones == ["SPACE1-1", "SPACE2-1", "SPACE3-1", "SPACE4-1", "SPACE5-1"]
    assert {t.kind for t in five.terminals} == {"AirTerminal:SingleDuct:VAV:Reheat"}
    assert all(t.minimum_fraction == 0.3 and t.air_loop == "VAV Sys 1" for t in five.terminals)
    assert five.neighbours["SPACE5-1"] == {"SPACE1-1", "SPACE2-1", "SPACE3-1", "SPACE4-1"}
    assert five.neighbours["SPACE1-1"] == {"SPACE2-1", "SPACE4-1", "SPACE5-1"}
    assert {"FanAvailSched", "ReheatCoilAvailSched", "CoolingCoilAvailSched"} \
        <= set(five.override_schedules)
    small = describe(small_office)
    assert "Attic" not in small.zones and len(small.zones) == 5
    assert {t.kind for t in small.terminals} == {"AirTerminal:SingleDuct:ConstantVolume:NoReheat"}
    assert len(set(small.loops)) == 5 and len({t.air_loop for t in small.terminals}) == 5
    assert "HVACOperationSchd" in small.override_schedules
    assert "ALWAYS_ON" not in small.override_schedules   # also used by lights and infiltration
    patched, _ = patch_epjson(small_office, small, PERIODS)
    diff = _diff(small_office, patched)
    assert set(diff) <= RUN_CONTROL, diff
    assert patched["Timestep"]["Timestep 1"]["number_of_timesteps_per_hour"] == 12
    flows = [a for a in patched["EnergyManagementSystem:Actuator"].values()
             if a["actuated_component_control_type"] == "Mass Flow Rate"]
    assert len(flows) == 5


def test_schedule_sets_the_plan_fraction_during_a_block(five_zone):
    layout = describe(five_zone)
    blocks = plan_blocks(layout.zones, 0.3, [SATURDAY], layout.neighbours, seed=1)
    assert len(blocks) == 5 and blocks[0].start == dt.datetime(2014, 10, 11, 8)
    table = schedule_table(layout, PERIODS[0][0], blocks)
    assert len(table) == 365 * 96
    for b in blocks:
        rows = table[(table.index >= b.start) & (table.index < b.end)]
        assert len(rows) == 8 and (rows[EXPERIMENT_SCHEDULE] == 1).all()
        for t in layout.terminals:
            assert (rows[fraction_schedule(t)] == b.fractions[t.zone]).all()
            assert b.fractions[b.target] == 1.0
    t = table.index
    outside = table[(t >= "2014-10-11 06:00") & (t < "2014-10-11 08:00")]
    assert len(outside) == 8
    assert (outside[EXPERIMENT_SCHEDULE] == 0).all()
    assert (outside[[fraction_schedule(t) for t in layout.terminals]] == 0.3).all().all()


def test_campaign_weeks_keep_excitation_weeks_first():
    weeks, weekends = campaign_weeks()
    assert len(weeks) == 11 and len(weekends) == 3
    weeks, weekends = campaign_weeks(2)
    assert weeks == [dt.date(2014, 10, 6), dt.date(2015, 4, 13)]
    assert weekends == [dt.date(2014, 10, 11), dt.date(2015, 4, 18)]
    with pytest.raises(ForeignBuildingError, match="between 1 and 11"):
        campaign_weeks(12)


def test_one_week_runs_and_fills_the_data_contract(week):
    site = load_site(week.out / "site.yaml")
    tel = load_telemetry(week.out / "telemetry.csv", site)
    assert len(tel.frame) == 7 * 96 and not tel.frame.isna().any().any()
    assert site.timezone == "Etc/GMT+6"          # the file keeps standard time (no DST object)
    assert len(site.boxes) == 5 and list(site.zones) == [f"SPACE{i}-1" for i in range(1, 6)]
    assert [(e.start.hour, e.end.hour) for e in site.experiments] == [(8, 18)]
    assert site.thermostat is not None and site.thermostat.heating_occupied == pytest.approx(22.2)
    model = Pipeline.from_site(week.out / "site.yaml").model()
    assert model is not None
    truth = pd.read_csv(week.out / "truth.csv", index_col=0)
    assert truth["people:zone:SPACE1-1"].max() > 0 and truth["window_solar:zone:SPACE1-1"].max() > 0
    assert (week.out / "building.idf").is_file() and (week.out / "building.epJSON").is_file()
    # the weather file it ran with, beside the site (its ground temperatures: F/C-factor faces)
    assert site.weather_file == Path("weather.epw") and site.weather_path.is_file()
    assert site.weather_path.read_text(errors="replace").startswith("LOCATION,Chicago")


def test_site_draft_of_the_run_input_checks_against_its_telemetry(week, tmp_path):
    """`zonecast site draft` on the input EnergyPlus ran gives the driver's zones, boxes and
    points (one naming convention), and the draft passes `zonecast check` on the run's
    telemetry as it is; its thermostat is the one EnergyPlus reported."""
    from typer.testing import CliRunner

    from zonecast.cli import app
    out = tmp_path / "site.yaml"
    res = CliRunner().invoke(app, ["site", "draft", "--idf", str(week.out / "building.epJSON"),
                                   "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert "5 zones, 5 boxes (5 with a discharge-air point)" in res.output
    drafted, ran = load_site(out), load_site(week.out / "site.yaml")
    assert drafted.zones == ran.zones and drafted.boxes == ran.boxes
    assert drafted.points == ran.points and drafted.timezone == ran.timezone
    t, r = drafted.thermostat, ran.thermostat
    assert (t.heating_occupied, t.heating_unoccupied, t.cooling_occupied, t.cooling_unoccupied) \
        == (r.heating_occupied, r.heating_unoccupied, r.cooling_occupied, r.cooling_unoccupied)
    assert t.occupied_hours == r.occupied_hours
    res = CliRunner().invoke(app, ["check", "--site", str(out), "--data", str(week.out)])
    assert res.exit_code == 0, res.output
    res = CliRunner().invoke(app, ["site", "draft", "--idf", str(week.out / "building.epJSON"),
                                   "--out", str(out)])
    assert res.exit_code == 2 and "exists; pass --force" in res.output


def test_max_block_raises_the_target_airflow(week):
    blocks = pd.read_csv(week.out / "experiments.csv")
    tel = week.telemetry
    local = tel.index.tz_convert("Etc/GMT+6")
    exp = np.zeros(len(tel), bool)
    for _, b in blocks.iterrows():
        exp |= (local >= pd.Timestamp(b.start)) & (local < pd.Timestamp(b.end))
    for _, b in blocks.iterrows():
        col = f"{b.target}_VAV_Reheat_flow"
        sel = (local >= pd.Timestamp(b.start)) & (local < pd.Timestamp(b.end))
        inside = tel.loc[sel, col].mean()
        outside = tel.loc[~exp & (local.day_of_week >= 5), col].median()
        assert inside > 2.5 * outside, (b.target, inside, outside)
        # the 08:00 row already shows the commanded step (docs/data.md time convention)
        assert tel.loc[sel, col].iloc[0] == pytest.approx(inside, rel=0.02)


def test_scheduled_inputs_flow_through_every_input_path(week, tmp_path):
    """NREL's 5-zone leaks by a Schedule:Compact and has ground-contact floors: the model
    takes both as scheduled inputs (after the five VAV boxes), the offline rows and the
    runner's row conversion give the same u and discharge-air rise, and the served inputs
    carry the schedules' airflows, the forecast outdoor air and the ground's month exactly.
    The file's infiltration schedule is 0 in this October week, so a daily one (the DOE
    small office's) stands in for it to see the values move."""
    from zonecast.estimator.artifact import load_model_file, write_model_file
    from zonecast.estimator.dataset import scheduled_inputs
    from zonecast.estimator.schedules import CompactSchedule
    from zonecast.estimator.streaming import OnlineEstimator, RowConverter, model_rows

    site_file = week.out / "site.yaml"
    pipe = Pipeline.from_site(site_file)
    st = pipe.model().structure
    leaks = [f"infiltration:SPACE{i}-1 Infil 1" for i in range(1, 6)]
    grounds = [f"ground:F{i}-1" for i in range(1, 6)]
    assert list(st.scheduled) == grounds + leaks
    assert st.hvac_boxes == list(pipe.site.boxes) and len(st.boxes) == 15
    daily = CompactSchedule.from_epjson("Quarter", {"data": [{"field": f} for f in (
        "Through: 12/31", "For: Weekdays", "Until: 06:00", 1.0, "Until: 22:00", 0.25,
        "Until: 24:00", 1.0, "For: AllOtherDays", "Until: 24:00", 1.0)]})
    for b in leaks:
        st.scheduled[b]["schedule"] = daily.to_dict()
    path = write_model_file(tmp_path / "model.json", site_file, structure=st,
                            room_volume=pipe.model().room_weights())
    bundle = load_model_file(path)
    assert bundle.model.structure.scheduled == st.scheduled
    tel = load_telemetry(week.out / "telemetry.csv", bundle.site)
    frame = tel.frame
    data = model_rows(bundle, frame)
    assert data.u.shape[1] == 15 and data.boxes[5:] == grounds + leaks
    leak = slice(10, 15)
    assert set(np.round(data.u[:, 10] / st.scheduled[leaks[0]]["flow"], 6)) == {0.25, 1.0}
    np.testing.assert_array_equal(data.reheat[:, leak],
                                  np.repeat((data.v[:, 0] - data.v[:, 1])[:, None], 5, axis=1))
    october = st.scheduled[grounds[0]]["monthly"][9]
    np.testing.assert_allclose(data.reheat[:, 5:10], october - data.v[:, [1] * 5], atol=1e-12)
    conv = RowConverter(bundle)
    ns = frame.index.as_unit("ns").asi8
    u, _, _, rise = conv.convert_rows(ns, frame[conv.points].to_numpy())
    np.testing.assert_array_equal(u[:, 5:], data.u[:, 5:])
    np.testing.assert_allclose(rise[:, 5:], data.reheat[:, 5:], rtol=0, atol=1e-12)
    est = OnlineEstimator(bundle)
    for k in range(2 * 96):
        est.advance(data.times[k], data.u[k], data.v[k], data.y[k], data.reheat[k])
    ins = est.forecast_inputs()
    ahead = est.time.value + 900 * 10**9 * np.arange(len(ins), dtype=np.int64)
    want = scheduled_inputs(st.scheduled, pd.DatetimeIndex(ahead, tz="UTC"), bundle.site)
    np.testing.assert_array_equal(ins[:, 5:15], want)
    assert len(np.unique(want[:, 5])) == 2                  # the day's two values ahead
    nb = 15
    np.testing.assert_allclose(ins[:, -5:], np.repeat((ins[:, nb] - ins[:, nb + 1])[:, None],
                                                      5, axis=1), rtol=0, atol=1e-12)
    np.testing.assert_allclose(ins[:, -10:-5], october - ins[:, [nb + 1] * 5], atol=1e-12)


def test_shading_flows_through_every_input_path(week, tmp_path):
    """NREL's 5-zone has overhangs over its south window and glass door
    (Shading:Zone:Detailed): the model shades its south column only; the runner's row
    conversion, in one batch and one row at a time (the day's sunlit fractions cached),
    gives the offline rows' numbers."""
    from dataclasses import replace

    from zonecast.estimator.artifact import load_model_file, write_model_file
    from zonecast.estimator.streaming import RowConverter, model_rows

    site_file = week.out / "site.yaml"
    pipe = Pipeline.from_site(site_file)
    st = pipe.model().structure
    assert sorted(e["name"] for e in st.shading) == ["DF-1", "WF-1"]
    assert {e["facade"] for e in st.shading} == {1}           # the building's south
    assert sum(e["share"] for e in st.shading) == pytest.approx(1.0)
    tel = load_telemetry(week.out / "telemetry.csv", pipe.site)
    shaded = pipe.data(tel)
    plain = Pipeline.from_site(site_file, options=replace(pipe.options, shading="none")).data(tel)
    np.testing.assert_array_equal(shaded.v[:, [0, 1, 2, 4, 5]], plain.v[:, [0, 1, 2, 4, 5]])
    day = plain.v[:, 3] > 50
    assert np.all(shaded.v[:, 3] <= plain.v[:, 3] + 1e-9)
    assert shaded.v[day, 3].sum() < 0.9 * plain.v[day, 3].sum()
    path = write_model_file(tmp_path / "model.json", site_file, structure=st,
                            room_volume=pipe.model().room_weights())
    bundle = load_model_file(path)
    assert bundle.model.structure.shading == st.shading
    data = model_rows(bundle, tel.frame)
    np.testing.assert_allclose(data.v, shaded.v, rtol=1e-12, atol=1e-9, equal_nan=True)
    conv = RowConverter(bundle)
    ns = tel.frame.index.as_unit("ns").asi8
    vals = tel.frame[conv.points].to_numpy()
    _, v, _, _ = conv.convert_rows(ns, vals)
    np.testing.assert_allclose(v, data.v, rtol=1e-12, atol=1e-9, equal_nan=True)
    rows = np.vstack([conv.convert_rows(ns[k:k + 1], vals[k:k + 1])[1] for k in range(len(ns))])
    np.testing.assert_allclose(rows, data.v, rtol=1e-12, atol=1e-9, equal_nan=True)


def _setpoints(days, hours, holiday=None, tz="America/Chicago"):
    """Two zones' reported set points over three weeks: 21/24 C in the occupied ``hours``
    of the weekdays ``days`` (per weekday its own span), 15.6/26.7 C otherwise."""
    idx = pd.date_range("2015-06-01", "2015-06-21 23:45", freq="15min", tz=tz)
    h = idx.hour + idx.minute / 60.0
    occ = np.zeros(len(idx), bool)
    for d, (h0, h1) in zip(days, hours):
        occ |= (idx.day_of_week == d) & (h >= h0) & (h < h1)
    if holiday is not None:
        occ &= idx.date != holiday
    frame = {}
    for z in ("A", "B"):
        frame[f"heating_setpoint:{z}"] = np.where(occ, 21.0, 15.6)
        frame[f"cooling_setpoint:{z}"] = np.where(occ, 24.0, 26.7)
    return pd.DataFrame(frame, index=idx.tz_convert("UTC"))


def test_thermostat_inferred_with_saturdays_and_holidays():
    from zonecast.testbed.foreign import infer_thermostat

    # Monday-Friday 06-20: the NREL 5-zone's pattern
    tru = _setpoints(range(5), [(6, 20)] * 5)
    th = infer_thermostat(tru, ["A", "B"], "America/Chicago", np.zeros(len(tru), bool))
    assert th["working_days"] == [0, 1, 2, 3, 4] and th["occupied_hours"] == [6.0, 20.0]
    assert th["holidays"] == [] and th["heating_occupied"] == 21.0
    # the DOE small office: weekdays 06-22, Saturdays 06-18, one weekday a holiday
    tru = _setpoints(range(6), [(6, 22)] * 5 + [(6, 18)], holiday=dt.date(2015, 6, 10))
    th = infer_thermostat(tru, ["A", "B"], "America/Chicago", np.zeros(len(tru), bool))
    assert th["working_days"] == [0, 1, 2, 3, 4, 5] and th["occupied_hours"] == [6.0, 22.0]
    assert th["holidays"] == ["2015-06-10"]
    # an experiment Saturday (set points widened) is not a holiday
    exp = np.asarray(tru.index.tz_convert("America/Chicago").date == dt.date(2015, 6, 13))
    th = infer_thermostat(tru, ["A", "B"], "America/Chicago", exp)
    assert "2015-06-13" not in th["holidays"]
    # no two levels: nothing inferred
    flat = tru.copy()
    flat[:] = 21.0
    assert infer_thermostat(flat, ["A", "B"], "America/Chicago", np.zeros(len(tru), bool)) is None


def test_a_pre96_file_says_it_needs_an_upgrade(tmp_path):
    """Without transition programs a pre-9.6 file's HVAC cannot be run: a clear error, not
    "no air terminal" (the reader kept only what the estimator uses)."""
    from zonecast.estimator.idf import _PRE96_SPACE_FIELD, find_energyplus, idf_objects

    if find_energyplus().transitions is not None:
        pytest.skip("this EnergyPlus has transition programs")
    lines = []  # the 5-zone file in 9.5's field order (no Space fields), declared 9.5
    for obj in idf_objects(FIVE_ZONE.read_text(encoding="latin-1")):
        cls, fields = obj[0], obj[1:]
        pos = _PRE96_SPACE_FIELD.get(cls.lower())
        if cls.lower() == "version":
            fields = ["9.5"]
        elif pos is not None and len(fields) > pos:
            fields = fields[:pos] + fields[pos + 1:]
        lines.append(cls + ", " + ", ".join(fields) + ";")
    old = tmp_path / "five_95.idf"
    old.write_text("\n".join(lines))
    with pytest.raises(ForeignBuildingError, match="predates EnergyPlus 9.6.*IDFVersionUpdater"):
        run_foreign(old, tmp_path / "out")

