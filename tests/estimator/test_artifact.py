"""The model artefact: model file + structure .npz (estimator/artifact.py).

A model file with its structure loads without EnergyPlus and gives a model that steps
bit for bit like the one built from the EnergyPlus file; files without a structure (schema
1, or written without one) still load by rebuilding it.
"""

from __future__ import annotations

import hashlib
import json

import numpy as np
import pytest
from zonecast.estimator import artifact
from zonecast.estimator.artifact import (
    ModelFileError,
    load_model_file,
    load_structure,
    save_structure,
    write_model_file,
)
from zonecast.estimator.pipeline import Pipeline, PipelineError


def test_model_file_defaults_and_errors(vb, bundle, tmp_path):
    assert bundle.model.params.as_dict()["gamma_IW"]["value"] == 9.0
    assert any("start values" in n for n in bundle.notes)
    assert bundle.profile.values.shape == (672, len(bundle.zones))
    bare = load_model_file(write_model_file(tmp_path / "m.json", vb / "site.yaml"))
    assert np.all(bare.profile.values == 0) and "no weekly" in " ".join(bare.notes)
    # model options round-trip; a file from before they existed is read as it was built
    assert bare.model.structure.options.window_solar == "surfaces"
    air = load_model_file(write_model_file(tmp_path / "a.json", vb / "site.yaml",
                                           model_options={"window_solar": "air"}))
    assert air.model.structure.options.window_solar == "air"
    star = load_model_file(write_model_file(tmp_path / "s.json", vb / "site.yaml",
                                            model_options={"interior_radiation": "star"}))
    assert star.model.structure.options.interior_radiation == "star"
    assert air.model.structure.options.interior_radiation == "none"  # a file not naming it
    split = load_model_file(write_model_file(tmp_path / "g.json", vb / "site.yaml",
                                             model_options={"internal_gains": "idf"}))
    assert split.model.structure.options.internal_gains == "idf"
    assert air.model.structure.options.internal_gains == "air"  # a file not naming it
    mirror = load_model_file(write_model_file(tmp_path / "ad.json", vb / "site.yaml",
                                              model_options={"adiabatic": "mirror"}))
    assert mirror.model.structure.options.adiabatic == "mirror"
    assert air.model.structure.options.adiabatic == "zero_flux"  # a file not naming it
    fine = load_model_file(write_model_file(tmp_path / "fl.json", vb / "site.yaml",
                                            model_options={"layers": "fine"}))
    assert fine.model.structure.options.layers == "fine"
    assert fine.model.structure.n > mirror.model.structure.n  # the virtual building's slabs
    assert air.model.structure.options.layers == "lumped"  # a file not naming it
    one = load_model_file(write_model_file(tmp_path / "im.json", vb / "site.yaml",
                                           model_options={"internal_mass": "one_face"}))
    assert one.model.structure.options.internal_mass == "one_face"
    assert air.model.structure.options.internal_mass == "both_faces"  # a file not naming it
    legacy = json.loads((tmp_path / "a.json").read_text())
    del legacy["model_options"]
    (tmp_path / "legacy.json").write_text(json.dumps(legacy))
    old = load_model_file(tmp_path / "legacy.json")
    assert old.model.structure.options.window_solar == "air"
    assert any("no model_options" in n for n in old.notes)
    cases = [
        ({"schema_version": 3, "site": str(vb / "site.yaml")},
         r"schema_version must be one of \[1, 2\]"),
        ({"schema_version": 1}, "'site' must be the path"),
        ({"schema_version": 1, "site": "nope.yaml"}, "not found"),
        ({"schema_version": 1, "site": str(vb / "site.yaml"), "parameters": {"gamma_XX": 1}},
         "unknown parameter 'gamma_XX'"),
        ({"schema_version": 1, "site": str(vb / "site.yaml"), "parameters": {"gamma_IW": -1}},
         "outside its bounds"),
        ({"schema_version": 1, "site": str(vb / "site.yaml"),
          "weekly_profile": {"values": [[1.0]]}}, r"expected \(672, 6\)"),
        ({"schema_version": 1, "site": str(vb / "site.yaml"), "noise": {"sigma_air": 0}},
         "positive number"),
        ({"schema_version": 1, "site": str(vb / "site.yaml"),
          "model_options": {"window_solar": "wall"}}, "window_solar must be 'surfaces', 'floor'"),
        ({"schema_version": 1, "site": str(vb / "site.yaml"),
          "model_options": {"colour": "red"}}, r"unknown model_options \['colour'\]"),
    ]
    for doc, msg in cases:
        path = tmp_path / "bad.json"
        path.write_text(json.dumps(doc))
        with pytest.raises(ModelFileError, match=msg):
            load_model_file(path)
    (tmp_path / "bad.json").write_text("{")
    with pytest.raises(ModelFileError, match="not valid JSON"):
        load_model_file(tmp_path / "bad.json")


def test_model_file_site_path_is_relative_across_folders(vb, tmp_path):
    """A model file written in another folder than the site's stores a relative path
    that loads from there (reproduce writes REPORT/model.json beside REPORT/campaign)."""
    out = tmp_path / "report" / "model.json"
    out.parent.mkdir()
    write_model_file(out, vb / "site.yaml", extra={"profile_weeks": []})
    doc = json.loads(out.read_text())
    assert not doc["site"].startswith("/") and doc["profile_weeks"] == []
    assert load_model_file(out).building == "office6"


def _same_structure(a, b) -> None:
    assert a.labels == b.labels and a.rooms == b.rooms and a.zones == b.zones
    assert a.boxes == b.boxes and a.cp_air == b.cp_air and a.options == b.options
    assert a.notes == b.notes and a.areas == b.areas
    assert set(a.window_area) == set(b.window_area)
    for r in a.window_area:
        assert np.array_equal(a.window_area[r], b.window_area[r])
    for name in ("capacity", "B_ig", "C", "room_of_box"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    for x, y in zip([a.A0, a.Bv0, *a.A_p, *a.Bv_p], [b.A0, b.Bv0, *b.A_p, *b.Bv_p]):
        assert (x != y).nnz == 0 and x.shape == y.shape
        assert np.array_equal(x.indptr, y.indptr) and np.array_equal(x.indices, y.indices)


def test_stored_structure_equals_the_one_built_from_the_idf_bit_for_bit(vb, bundle, tmp_path):
    pipe = Pipeline.from_site(vb / "site.yaml")
    built = pipe.structure()
    _same_structure(bundle.model.structure, built)
    assert bundle.room_volume == pipe.room_volume
    # the same model steps the same, to the bit, on real inputs
    tel = pipe.telemetry(vb)
    d = pipe.data(tel)
    rebuilt = pipe.model(bundle.model.params)
    rows = slice(0, 96)
    a = bundle.model.simulate(20.0, d.u[rows], d.v[rows])
    b = rebuilt.simulate(20.0, d.u[rows], d.v[rows])
    assert np.array_equal(a.x, b.x)
    # round trip of the file itself
    path = save_structure(tmp_path / "s.npz", built, pipe.room_volume)
    again, volume = load_structure(path)
    _same_structure(again, built)
    assert volume == pipe.room_volume


def test_model_file_with_structure_loads_without_energyplus(vb, monkeypatch):
    def no_energyplus(*args, **kwargs):
        raise AssertionError("EnergyPlus was called")

    monkeypatch.setattr(artifact, "read_building", no_energyplus)
    doc = json.loads((vb / "model.json").read_text())
    assert doc["schema_version"] == 2 and doc["structure"] == "model.npz"
    b = load_model_file(vb / "model.json")
    assert b.model.params["gamma_IW"] == 9.0
    assert not any("rebuilt" in n for n in b.notes)
    # without a structure, the file needs the IDF (and says so in its notes)
    legacy = {k: v for k, v in doc.items() if not k.startswith("structure")}
    (vb / "legacy-schema.json").write_text(json.dumps({**legacy, "schema_version": 1}))
    with pytest.raises(AssertionError, match="EnergyPlus was called"):
        load_model_file(vb / "legacy-schema.json")
    monkeypatch.undo()
    old = load_model_file(vb / "legacy-schema.json")
    assert any("rebuilt from the site's EnergyPlus file" in n for n in old.notes)
    _same_structure(old.model.structure, b.model.structure)


def test_structure_file_errors_say_what_to_fix(vb, tmp_path):
    doc = json.loads((vb / "model.json").read_text())
    doc["site"] = str(vb / "site.yaml")
    npz = vb / "model.npz"

    def load(**change):
        path = tmp_path / "m.json"
        path.write_text(json.dumps({**doc, **change}))
        return load_model_file(path)

    with pytest.raises(ModelFileError, match="structure file .* not found"):
        load(structure="missing.npz")
    with pytest.raises(ModelFileError, match="does not match structure_sha256"):
        load(structure=str(npz), structure_sha256="0" * 64)
    with pytest.raises(ModelFileError, match="model_options .* differ from the options"):
        load(structure=str(npz), model_options={"window_solar": "air"})
    assert load(structure=str(npz)).model.n == load_model_file(vb / "model.json").model.n
    assert doc["structure_sha256"] == hashlib.sha256(npz.read_bytes()).hexdigest()
    with pytest.raises(ValueError, match="give room_volume"):
        write_model_file(tmp_path / "x.json", vb / "site.yaml",
                         structure=load_model_file(vb / "model.json").model.structure)


def test_pipeline_rejects_an_unknown_weekend_gains_mode(vb):
    pipe = Pipeline.from_site(vb / "site.yaml")
    with pytest.raises(PipelineError,
                       match="use 'auto', 'none', 'known', 'scaled', 'daytime' or 'metered'"):
        pipe.identify(pipe.data(pipe.telemetry(vb)), weekend_gains="sometimes")
    with pytest.raises(PipelineError, match="films='radiant': use 'combined', 'convective' or 'idf'"):
        pipe.identify(pipe.data(pipe.telemetry(vb)), films="radiant")
    with pytest.raises(PipelineError, match="positive_priors='gamma': use 'normal' or 'log'"):
        pipe.identify(pipe.data(pipe.telemetry(vb)), positive_priors="gamma")


def test_weekend_daytime_shape_marks_weekend_days_between_8_and_18_local(vb):
    from zonecast.estimator.pipeline import WEEKEND_DAY_GAIN, weekend_daytime_shape

    pipe = Pipeline.from_site(vb / "site.yaml")
    data = pipe.data(pipe.telemetry(vb))
    shape = weekend_daytime_shape(data)
    local = data.local_times()
    assert shape.shape == (len(data.times), len(data.zones))
    on = shape[:, 0] > 0
    assert np.all(shape[on] == WEEKEND_DAY_GAIN) and np.all(shape[~on] == 0)
    assert set(local[on].day_of_week) == {5, 6}
    assert local[on].hour.min() == 8 and local[on].hour.max() == 17
    # every weekend row in those hours is marked (4 rows an hour, 10 hours a day)
    weekend_days = len({d for d, w in zip(local.date, local.day_of_week) if w >= 5})
    assert on.sum() <= weekend_days * 40 and on.sum() >= (weekend_days - 2) * 40


def test_weekend_metered_gains_are_the_weekend_rise_above_the_night_base_per_floor_area(vb):
    """The virtual building's zone meters (lights + plug loads) on Saturday and Sunday
    rows, less the median of the weekend readings between 00 and 06 h local, per m2 of
    the zone's floor; 0 on working days, on a weekend row whose meter did not report and
    for a zone without a meter; 'metered' without meters is refused."""
    import dataclasses

    from zonecast.estimator.pipeline import weekend_metered_gains

    pipe = Pipeline.from_site(vb / "site.yaml")
    data = pipe.data(pipe.telemetry(vb))
    assert data.power is not None and np.isfinite(data.power).all()
    area = pipe.zone_floor_areas()
    b = pipe.building()
    assert area.sum() == pytest.approx(sum(b.zones[r].floor_area for rs in pipe.site.zones.values()
                                           for r in rs))
    local = data.local_times()
    weekend = np.asarray(local.day_of_week >= 5)
    night = weekend & np.asarray(local.hour < 6)
    known = weekend_metered_gains(data, area)
    np.testing.assert_array_equal(pipe.weekend_known_gains(data, "metered"), known)
    assert pipe.weekend_known_gains(data, "daytime") is None
    assert np.all(known[~weekend] == 0)
    for j in range(len(data.zones)):
        base = np.median(data.power[night, j])
        np.testing.assert_allclose(known[weekend, j],
                                   np.maximum(data.power[weekend, j] - base, 0) / area[j])
    assert known[weekend].max() > 0.5  # the weekend days' lights and plugs rise at times
    power = data.power.copy()
    k = int(np.flatnonzero(weekend & np.asarray(local.hour == 12))[0])
    power[k, 0] = np.nan
    power[:, 1] = np.nan
    alt = weekend_metered_gains(dataclasses.replace(data, power=power), area)
    assert alt[k, 0] == 0 and np.all(alt[:, 1] == 0)
    np.testing.assert_array_equal(np.delete(alt[:, 0], k), np.delete(known[:, 0], k))
    np.testing.assert_array_equal(alt[:, 2:], known[:, 2:])
    with pytest.raises(PipelineError, match="needs electricity meters: map .*points.power"):
        pipe.identify(dataclasses.replace(data, power=None), weekend_gains="metered")


class _Stop(Exception):
    """Raised by the stand-in of identify() once it has seen its arguments."""


def _capture_identify(monkeypatch, module) -> list[dict]:
    """Replace ``module.identify`` by a stand-in that records its keyword arguments and
    raises :class:`_Stop`; returns the list they go into."""
    seen: list[dict] = []

    def fake(*args, **kwargs):
        seen.append(kwargs)
        raise _Stop

    monkeypatch.setattr(module, "identify", fake)
    return seen


def test_x0_meters_tells_the_x0_filter_the_working_days_metered_gains(vb, monkeypatch):
    """Pipeline.identify(x0_meters=True) hands identify, as the x(0) filter's gains, each
    zone's metered rise above its weekend night base on the working days
    (weekend_metered_gains(every_day=True)) and nothing on the weekends, whose gains are
    the weekend mode's; False none; "auto" (the default) the same as True where the site
    has meters, none without. True is refused without meters and with x0_profile_days,
    which tells the filter the same days' gains another way."""
    import dataclasses

    import zonecast.estimator.pipeline as pl
    from zonecast.estimator.pipeline import weekend_metered_gains

    pipe = Pipeline.from_site(vb / "site.yaml")
    data = pipe.data(pipe.telemetry(vb))
    area = pipe.zone_floor_areas()
    every = weekend_metered_gains(data, area, every_day=True)
    weekend = np.asarray(data.local_times().day_of_week >= 5)
    np.testing.assert_array_equal(every[weekend], weekend_metered_gains(data, area)[weekend])
    assert every[~weekend].max() > 2.0  # the working days' lights and plugs
    seen = _capture_identify(monkeypatch, pl)
    for x0_meters in (True, False, "auto"):
        with pytest.raises(_Stop):
            pipe.identify(data, train=["2015-04-18"], validation=[], x0_meters=x0_meters)
    with pytest.raises(_Stop):  # "auto" without meters: off
        pipe.identify(dataclasses.replace(data, power=None), train=["2015-04-18"],
                      validation=[], weekend_gains="daytime")
    told, untold, auto, no_meters = seen
    assert untold["x0_gains"] is None and no_meters["x0_gains"] is None
    np.testing.assert_array_equal(told["x0_gains"][~weekend], every[~weekend])
    assert np.all(told["x0_gains"][weekend] == 0)
    np.testing.assert_array_equal(auto["x0_gains"], told["x0_gains"])
    with pytest.raises(PipelineError, match="x0_meters='yes': use True, False or 'auto'"):
        pipe.identify(data, train=["2015-04-18"], validation=[], x0_meters="yes")
    with pytest.raises(PipelineError, match="needs electricity meters"):
        pipe.identify(dataclasses.replace(data, power=None), train=["2015-04-18"],
                      validation=[], weekend_gains="daytime", x0_meters=True)
    with pytest.raises(PipelineError, match="x0_meters and x0_profile_days .* choose one"):
        pipe.identify(data, train=["2015-04-18"], validation=[], x0_meters=True,
                      x0_profile_days=2)


def test_constant_gains_from_the_meters_are_each_zones_night_base(vb, monkeypatch):
    """Pipeline.identify(constant_gains="meters") starts each metered zone's c_IG at its
    weekend night base per m2 of floor (metered_base_gains: the median of its Saturday and
    Sunday readings between 00 and 06 h local) and holds it there with a prior whose sd is
    the meters' accuracy; a zone whose meter never reported keeps the handbook prior;
    "fitted" (the default) keeps every handbook prior; without meters, without the
    building's priors or with an unknown mode it says what to give."""
    import dataclasses

    import zonecast.estimator.pipeline as pl
    from zonecast.estimator.pipeline import (
        METERED_BASE_SD_MIN,
        METERED_BASE_SD_REL,
        metered_base_gains,
    )

    pipe = Pipeline.from_site(vb / "site.yaml")
    data = pipe.data(pipe.telemetry(vb))
    area = pipe.zone_floor_areas()
    local = data.local_times()
    night = np.asarray(local.day_of_week >= 5) & np.asarray(local.hour < 6)
    base = metered_base_gains(data, area)
    for j in range(len(data.zones)):
        assert base[j] == pytest.approx(np.median(data.power[night, j]) / area[j], rel=1e-12)
    assert np.all(base > 0.5)  # night lighting and standby plug loads
    power = data.power.copy()
    power[:, 1] = np.nan
    partial = dataclasses.replace(data, power=power)
    assert np.isnan(metered_base_gains(partial, area)[1])
    seen = _capture_identify(monkeypatch, pl)
    for d, mode in ((data, "fitted"), (data, "meters"), (partial, "meters")):
        with pytest.raises(_Stop):
            pipe.identify(d, train=["2015-04-18"], validation=[], constant_gains=mode)
    fitted, metered, part = seen
    names = [f"c_IG[{z}]" for z in data.zones]
    handbook = fitted["priors"][names[0]]
    assert all(fitted["priors"][n] == handbook for n in names)
    assert handbook.sd >= 5.0  # the paper's c_IG: weakly held
    for j, n in enumerate(names):
        prior = metered["priors"][n]
        assert prior.mean == pytest.approx(base[j])
        assert prior.sd == pytest.approx(max(METERED_BASE_SD_REL * base[j],
                                             METERED_BASE_SD_MIN))
        assert "metered" in prior.source
    start = dict(zip(pl.ParameterSet(list(pipe.site.zones),
                                     extra=pipe.structure().extra_params).param_names,
                     metered["start"]))
    assert [start[n] for n in names] == pytest.approx(list(base))
    assert part["priors"][names[1]] == handbook
    assert part["priors"][names[0]].mean == pytest.approx(base[0])
    # the other parameters' priors are the same in both modes
    assert {k: v for k, v in metered["priors"].items() if k not in names} == \
        {k: v for k, v in fitted["priors"].items() if k not in names}
    with pytest.raises(PipelineError, match="constant_gains='meters' needs electricity meters"):
        pipe.identify(dataclasses.replace(data, power=None), train=["2015-04-18"],
                      validation=[], weekend_gains="daytime", constant_gains="meters")
    with pytest.raises(PipelineError, match="keep priors=True"):
        pipe.identify(data, train=["2015-04-18"], validation=[], priors=False,
                      constant_gains="meters")
    with pytest.raises(PipelineError, match="constant_gains='known': use 'fitted' or 'meters'"):
        pipe.identify(data, train=["2015-04-18"], validation=[], constant_gains="known")


def test_metered_mode_fits_the_daytime_scale_with_the_metered_gains_known(vb, monkeypatch):
    """Pipeline.identify(weekend_gains="metered") hands identify the metered gains as known
    f_IG and the daytime shape to scale with a prior centred on 0 (the shape stands for the
    lights and plug loads the meters now give); "daytime" the shape alone, prior 1 ± 1."""
    import zonecast.estimator.pipeline as pl

    pipe = Pipeline.from_site(vb / "site.yaml")
    data = pipe.data(pipe.telemetry(vb))
    seen = _capture_identify(monkeypatch, pl)
    for mode in ("metered", "daytime"):
        with pytest.raises(_Stop):
            pipe.identify(data, train=["2015-04-18"], validation=[], weekend_gains=mode)
    np.testing.assert_array_equal(seen[0]["f_ig"], pipe.weekend_known_gains(data, "metered"))
    assert seen[0]["f_ig"].any()
    for kw in seen:
        np.testing.assert_array_equal(kw["gain_shape"], pl.weekend_daytime_shape(data))
    assert seen[1]["f_ig"] is None
    assert seen[0]["shape_prior"] == pl.METERED_SHAPE_PRIOR == (0.0, 1.0)
    assert seen[1]["shape_prior"] == (1.0, 1.0)


def test_operating_films_scale_the_pipelines_films_and_keep_the_identified_model(
        vb, monkeypatch):
    """Pipeline.identify(operating_films="natural") on a TARP building: the result's model
    keeps the identified films (Table 2), the pipeline's parameters (gains, forecasts, the
    model file) are the films times OPERATING_FILMS and every other parameter as
    identified; "none", the default, keeps the identified films."""
    import types

    import zonecast.estimator.pipeline as pl
    from zonecast.estimator.priors import OPERATING_FILMS

    pipe = Pipeline.from_site(vb / "site.yaml")
    assert pipe.building().inside_convection == "TARP"
    data = pipe.data(pipe.telemetry(vb))
    fitted = pipe.model().params.copy({"gamma_IW": 3.0, "gamma_floor": 2.0, "gamma_ceil": 1.5})

    def fake(model, *args, **kwargs):
        return types.SimpleNamespace(model=pipe.model(fitted), weekend_gains=None,
                                     weekend_metered_ratio=None, operating_films=None,
                                     to_dict=dict)

    monkeypatch.setattr(pl, "identify", fake)
    res = pipe.identify(data, train=["2015-04-18"], validation=[], operating_films="natural")
    assert res.operating_films == OPERATING_FILMS
    np.testing.assert_array_equal(res.model.params.values, fitted.values)
    for name in pipe.params.param_names:
        factor = OPERATING_FILMS.get(name, 1.0)
        assert pipe.params[name] == pytest.approx(fitted[name] * factor, rel=1e-12)
    assert pipe.params["gamma_floor"] == pytest.approx(2.0 / 1.30)
    res = pipe.identify(data, train=["2015-04-18"], validation=[])  # the default: "none"
    assert res.operating_films is None
    np.testing.assert_array_equal(pipe.params.values, fitted.values)
    with pytest.raises(PipelineError, match="operating_films='always': use 'natural' or 'none'"):
        pipe.identify(data, operating_films="always")


def test_weekend_metered_ratio_is_the_weekend_daytime_rise_over_the_working_days(vb):
    """The building's summed meters: mean between 08 and 18 h less the median between 00
    and 06 h local, weekends over working days; rows where a zone's meter is unknown are
    left out; None without meters or without a working-day rise."""
    import dataclasses

    from zonecast.estimator.pipeline import weekend_metered_ratio

    pipe = Pipeline.from_site(vb / "site.yaml")
    data = pipe.data(pipe.telemetry(vb))
    total = data.power.sum(axis=1)
    local = data.local_times()
    weekend, hour = np.asarray(local.day_of_week >= 5), np.asarray(local.hour)
    day, night = (hour >= 8) & (hour < 18), hour < 6

    def rise(days):
        return total[days & day].mean() - np.median(total[days & night])

    ratio = weekend_metered_ratio(data)
    assert ratio == pytest.approx(rise(weekend) / rise(~weekend), rel=1e-12)
    assert 0.0 < ratio < 0.15  # office6: nobody at weekends, cleaning and visits only
    # twice the weekend daytime rise of every zone doubles the ratio
    more = data.power.copy()
    on = weekend & day
    base = np.median(data.power[weekend & night], axis=0)
    more[on] = base + 2.0 * (data.power[on] - base)
    doubled = weekend_metered_ratio(dataclasses.replace(data, power=more))
    assert doubled == pytest.approx(2.0 * ratio, rel=0.05)
    gap = data.power.copy()
    gap[np.flatnonzero(on)[:40], 0] = np.nan  # a meter's gap: those rows are left out
    assert np.isfinite(weekend_metered_ratio(dataclasses.replace(data, power=gap)))
    assert weekend_metered_ratio(dataclasses.replace(data, power=None)) is None
    flat = np.ones_like(data.power)
    assert weekend_metered_ratio(dataclasses.replace(data, power=flat)) is None


def test_auto_weekend_gains_take_the_meters_only_where_the_weekends_are_occupied(
        vb, monkeypatch):
    """weekend_gains="auto" (the default) fits as "metered" when the meters' weekend rise
    is at least METERED_OCCUPIED_RATIO of the working days', else as "daytime" (and so
    without meters); the result says which mode and ratio."""
    import dataclasses

    import zonecast.estimator.pipeline as pl

    pipe = Pipeline.from_site(vb / "site.yaml")
    data = pipe.data(pipe.telemetry(vb))
    seen = _capture_identify(monkeypatch, pl)
    ratio = pl.weekend_metered_ratio(data)
    for threshold, expect in ((ratio + 0.01, "daytime"), (ratio - 0.01, "metered")):
        monkeypatch.setattr(pl, "METERED_OCCUPIED_RATIO", threshold)
        with pytest.raises(_Stop):
            pipe.identify(data, train=["2015-04-18"], validation=[])
        kw = seen[-1]
        if expect == "metered":
            np.testing.assert_array_equal(kw["f_ig"], pipe.weekend_known_gains(data, "metered"))
            assert kw["shape_prior"] == pl.METERED_SHAPE_PRIOR
        else:
            assert kw["f_ig"] is None and kw["shape_prior"] == (1.0, 1.0)
    with pytest.raises(_Stop):  # no meters: daytime, whatever the threshold
        pipe.identify(dataclasses.replace(data, power=None), train=["2015-04-18"],
                      validation=[])
    assert seen[-1]["f_ig"] is None
    monkeypatch.undo()
    assert pl.METERED_OCCUPIED_RATIO == 0.15


def test_structure_files_without_the_horizontal_column_still_load(vb, bundle, tmp_path):
    """Structure files written before the roofs' solH column have six columns in their
    B_v blocks: they load with a seventh, empty one, and step exactly as before."""
    path = save_structure(tmp_path / "s.npz", bundle.model.structure, bundle.room_volume)
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files}
    for key in [k for k in arrays if k.startswith("Bv") and k.endswith(".shape")]:
        assert arrays[key][1] == 7
        name = key[:-len(".shape")]
        assert (arrays[f"{name}.indices"] < 6).all()  # office6 has no roof: solH unused
        arrays[key] = np.array([arrays[key][0], 6])
    old = tmp_path / "old.npz"
    with old.open("wb") as fh:
        np.savez(fh, **arrays)
    again, _ = load_structure(old)
    assert again.Bv0.shape[1] == 7 and all(m.shape[1] == 7 for m in again.Bv_p)
    assert (again.Bv0 != bundle.model.structure.Bv0).nnz == 0
    arrays["Bv0.shape"] = np.array([arrays["Bv0.shape"][0], 5])
    with (tmp_path / "bad.npz").open("wb") as fh:
        np.savez(fh, **arrays)
    with pytest.raises(ValueError, match="B_v has 5 columns"):
        load_structure(tmp_path / "bad.npz")


@pytest.mark.parametrize("mode", ["operating", "day", "all"])
def test_weekly_profile_fills_the_empty_day_by_the_sites_calendar(vb, monkeypatch, mode):
    """Pipeline.weekly_profile hands the site's thermostat working days and occupied start
    to fixed_profile as forecast.PROFILE_FILL says; an unknown mode is an error."""
    from zonecast.estimator import forecast, pipeline

    pipe = Pipeline.from_site(vb / "site.yaml")
    data = pipe.data(pipe.telemetry(vb))
    seen = {}

    def capture(d, tracks, working_days=None, day_start=0.0):
        seen.update(days=working_days, start=day_start, n=len(tracks))
        return "profile"

    monkeypatch.setattr(pipeline, "track_week", lambda *a, **k: None)
    monkeypatch.setattr(pipeline, "fixed_profile", capture)
    monkeypatch.setattr(forecast, "PROFILE_FILL", mode)
    assert pipe.weekly_profile(data) == "profile"
    th = pipe.site.thermostat
    assert seen["n"] == 3
    assert seen["days"] == (None if mode == "all" else th.working_days)
    assert seen["start"] == (th.occupied_hours[0] if mode == "operating" else 0.0)
    monkeypatch.setattr(forecast, "PROFILE_FILL", "weekday")
    with pytest.raises(PipelineError, match="PROFILE_FILL 'weekday': use 'operating'"):
        pipe.weekly_profile(data)


def test_weekly_profile_counts_round_trip_and_bad_counts_say_so(vb, tmp_path):
    """A model file keeps the weeks behind each profile value (0: a bin fill_profile
    filled); a file without them counts every finite value as seen; bad counts are an
    error naming the field."""
    from zonecast.estimator.artifact import ModelFileError, load_model_file, write_model_file

    pipe = Pipeline.from_site(vb / "site.yaml")
    zones = list(pipe.site.zones)
    values = np.full((672, len(zones)), 2.0)
    counts = np.full((672, len(zones)), 3)
    counts[:96] = 0  # Monday filled
    kw = {"structure": pipe.structure(), "room_volume": pipe.room_volume}
    # zones in another order: the counts follow their columns
    order = zones[::-1]
    write_model_file(tmp_path / "m.json", vb / "site.yaml",
                     weekly_profile={"zones": order, "values": values.tolist(),
                                     "counts": counts[:, ::-1].tolist()}, **kw)
    np.testing.assert_array_equal(load_model_file(tmp_path / "m.json").profile.counts, counts)
    write_model_file(tmp_path / "old.json", vb / "site.yaml",
                     weekly_profile={"zones": zones, "values": values.tolist()}, **kw)
    assert (load_model_file(tmp_path / "old.json").profile.counts == 1).all()
    for bad in (counts[:10].tolist(), (counts - 4).tolist(), (counts + 0.5).tolist()):
        write_model_file(tmp_path / "bad.json", vb / "site.yaml",
                         weekly_profile={"zones": zones, "values": values.tolist(),
                                         "counts": bad}, **kw)
        with pytest.raises(ModelFileError, match="weekly_profile.counts must be whole"):
            load_model_file(tmp_path / "bad.json")


def test_reheat_leak_scales_the_boxes_reheat_everywhere_after_the_fit(vb, monkeypatch):
    """Pipeline.fit_reheat_leak: the gains of the weeks tracked with the heat as measured,
    their excitation rows left out, go to gains.fit_reheat_leak with each zone's reheat
    heat per floor area; each site box's reheat heat is then scaled by 1 + k of its zone in
    every model the pipeline makes and in the model file, which reads back the same; a bad
    factor in a file says what to fix."""
    import zonecast.estimator.pipeline as pl
    from zonecast.estimator.forecast import zone_floor_area
    from zonecast.estimator.gains import ReheatLeak
    from zonecast.estimator.model import BilinearModel

    pipe = Pipeline.from_model_file(vb / "model.json")
    data = pipe.data(pipe.telemetry(vb))
    assert np.any(data.reheat), "the virtual building's boxes must reheat in April"
    st = pipe.structure()
    seen = {}

    def spy(times, f_ig, q, timezone, **kw):
        seen.update(times=times, f=f_ig, q=q, timezone=timezone)
        k = np.linspace(0.1, 0.3, f_ig.shape[1])
        return ReheatLeak(k, k, np.full_like(k, 0.01), len(times))

    monkeypatch.setattr(pl, "fit_reheat_leak", spy)
    leak = pipe.fit_reheat_leak(data)
    assert seen["timezone"] == data.timezone and seen["f"].shape == seen["q"].shape
    assert seen["f"].shape[1] == len(st.zones)
    assert np.all(np.isnan(seen["f"][data.excitation[np.searchsorted(data.times,
                                                                     seen["times"])]]))
    zone_of_box = st.state_zones()[np.asarray(st.room_of_box)]
    rows = np.searchsorted(data.times, seen["times"])
    heat = st.options.cp_air * data.u[rows] * data.reheat[rows]  # [W] per box
    area = zone_floor_area(pipe.model())
    for j in range(len(st.zones)):
        mine = [i for i, b in enumerate(st.boxes) if b in pipe.site.boxes and zone_of_box[i] == j]
        np.testing.assert_allclose(seen["q"][:, j], heat[:, mine].sum(axis=1) / area[j],
                                   rtol=1e-9, atol=1e-12)
    assert np.nanmax(seen["q"]) > 1.0  # W/m2: the boxes reheat
    for i, b in enumerate(st.boxes):
        want = 1.0 + leak.k[zone_of_box[i]] if b in pipe.site.boxes else 1.0
        assert pipe.reheat_scale[i] == pytest.approx(want)
    model = pipe.model()
    np.testing.assert_array_equal(model.reheat_scale, pipe.reheat_scale)
    np.testing.assert_array_equal(model.with_params({"gamma_IW": 5.0}).reheat_scale,
                                  pipe.reheat_scale)
    plain = BilinearModel(st, model.params)
    u, r = np.full(len(st.boxes), 0.2), np.full(len(st.boxes), 10.0)
    np.testing.assert_allclose(model.reheat_forcing(u, r),
                               plain.reheat_forcing(u * pipe.reheat_scale, r))
    # drawn from the faces instead: the air gets the same, the total heat is the measured one
    faces = BilinearModel(st, model.params, reheat_scale=pipe.reheat_scale,
                          reheat_from_faces=True)
    air = st.air_states()
    np.testing.assert_allclose(faces.reheat_forcing(u, r)[air], model.reheat_forcing(u, r)[air])
    measured = st.capacity @ plain.reheat_forcing(u, r)
    assert st.capacity @ faces.reheat_forcing(u, r) == pytest.approx(measured, rel=1e-9)
    assert st.capacity @ model.reheat_forcing(u, r) > 1.05 * measured  # "added": more heat
    assert np.all(faces.reheat_forcing(u, r)[np.setdiff1d(np.arange(st.n), air)] <= 0)
    # the model file keeps it; the service's bundle and a new pipeline read it back
    path = pipe.write_model_file(vb / "model-reheat-leak.json")
    doc = json.loads(path.read_text())
    assert set(doc["reheat_scale"]) == set(pipe.site.boxes)
    assert doc["reheat_leak"]["zones"][next(iter(st.zones))]["k"] == pytest.approx(leak.k[0])
    again = Pipeline.from_model_file(path)
    np.testing.assert_allclose(again.model().reheat_scale, pipe.reheat_scale)
    np.testing.assert_allclose(load_model_file(path).model.reheat_scale, pipe.reheat_scale)
    assert doc["reheat_from_faces"] is False
    doc["reheat_from_faces"] = True
    path.write_text(json.dumps(doc))
    assert load_model_file(path).model.reheat_from_faces
    assert Pipeline.from_model_file(path).model().reheat_from_faces
    doc["reheat_from_faces"] = "yes"
    path.write_text(json.dumps(doc))
    with pytest.raises(ModelFileError, match="'reheat_from_faces' must be true or false"):
        load_model_file(path)
    doc["reheat_from_faces"] = False
    doc["reheat_scale"][next(iter(pipe.site.boxes))] = -1.0
    path.write_text(json.dumps(doc))
    with pytest.raises(ModelFileError, match=r"reheat_scale\[.*\] must be a number in \[0, 10\)"):
        load_model_file(path)
    doc["reheat_scale"] = {"no-such-box": 1.2}
    path.write_text(json.dumps(doc))
    with pytest.raises(ModelFileError, match="reheat_scale names boxes the model does not have"):
        load_model_file(path)
    with pytest.raises(ValueError, match="reheat_scale must be finite and >= 0"):
        BilinearModel(st, model.params, reheat_scale=-1.0)
    # a new identification sees the reheat as measured again
    import types

    seen_scale = []

    def fake(m, *args, **kwargs):
        seen_scale.append(m.reheat_scale.copy())
        return types.SimpleNamespace(model=m, weekend_gains=None, weekend_metered_ratio=None,
                                     operating_films=None, to_dict=dict)

    monkeypatch.setattr(pl, "identify", fake)
    pipe.identify(data, train=["2015-04-18"], validation=[])
    assert np.all(seen_scale[0] == 1.0) and pipe.reheat_scale is None
    with pytest.raises(PipelineError, match="reheat_leak='always': use 'none' or 'added' or 'from_faces'"):
        pl.check_reheat_leak("always")


def test_operating_films_auto_takes_the_ratios_only_when_operation_asks(vb, monkeypatch):
    """Pipeline.fit_operating_films: the reheat leak of every zone at the identified films
    (gains.fit_reheat_leak, measured and not kept) decides; the natural-convection ratios
    are applied when the zones' precision-weighted mean k exceeds 3 standard errors, the
    identified films stay otherwise, and nothing is measured for a building without a
    natural-convection algorithm or without reheat."""
    import dataclasses
    import types

    import zonecast.estimator.pipeline as pl
    from zonecast.estimator.gains import ReheatLeak
    from zonecast.estimator.priors import OPERATING_FILMS

    pipe = Pipeline.from_model_file(vb / "model.json")
    data = pipe.data(pipe.telemetry(vb))  # one week tracked per fit (weeks=[0]) for speed
    with pytest.raises(PipelineError, match=r"call identify\(\) first"):
        pipe.fit_operating_films(data, weeks=[0])
    base = pipe.params
    pipe.identification = types.SimpleNamespace(model=pipe.model(), operating_films=None,
                                                operating_films_test=None)
    # a model file's pipeline reads no IDF: the building's algorithm is EnergyPlus's default
    monkeypatch.setattr(pipe, "_building_or_none",
                        lambda: types.SimpleNamespace(inside_convection="TARP"))
    p = len(pipe.site.zones)
    calls = []

    def leak_of(fitted, se):
        def spy(times, f_ig, q, timezone, **kw):
            calls.append(f_ig.shape)
            return ReheatLeak(np.asarray(fitted, float), np.asarray(fitted, float),
                              np.asarray(se, float), len(times))
        return spy

    # every zone's air answers the reheat too weakly: the operating films
    monkeypatch.setattr(pl, "fit_reheat_leak", leak_of([0.2] * p, [0.02] * p))
    got = pipe.fit_operating_films(data, weeks=[0])
    assert got == OPERATING_FILMS and pipe.identification.operating_films == OPERATING_FILMS
    for name, factor in OPERATING_FILMS.items():
        assert pipe.params[name] == pytest.approx(base[name] * factor)
    assert pipe.params["gamma_EW"] == base["gamma_EW"]
    test = pipe.identification.operating_films_test
    assert test["applied"] and test["k_mean"] == pytest.approx(0.2)
    assert test["stderr"] == pytest.approx(0.02 / np.sqrt(p))
    assert pipe.reheat_scale is None and pipe.reheat_leak is None  # measured, not kept
    assert pipe.model().params["gamma_floor"] == pytest.approx(base["gamma_floor"] / 1.30)
    # a precise zone that says the opposite outweighs an imprecise one: the films stay
    monkeypatch.setattr(pl, "fit_reheat_leak",
                        leak_of([0.5] + [-0.1] * (p - 1), [1.0] + [0.01] * (p - 1)))
    assert pipe.fit_operating_films(data, weeks=[0]) == {}
    assert pipe.params["gamma_floor"] == base["gamma_floor"]
    assert not pipe.identification.operating_films_test["applied"]
    assert pipe.identification.operating_films_test["k_mean"] < 0
    # a mean k within its noise: the films stay
    monkeypatch.setattr(pl, "fit_reheat_leak", leak_of([0.01] * p, [0.02] * p))
    assert pipe.fit_operating_films(data, weeks=[0]) == {}
    assert pipe.identification.operating_films is None
    # the reheat leak that follows at the same films and weeks reuses the tracked gains
    tracked = []
    real_track = pl.track_week
    monkeypatch.setattr(pl, "track_week", lambda *a, **k: tracked.append(1) or real_track(*a, **k))
    n = len(calls)
    assert pipe.fit_reheat_leak(data, weeks=[0]) is not None
    assert not tracked and len(calls) == n + 1
    pipe.params = base.copy({"gamma_IW": base["gamma_IW"] * 0.5})  # other films: tracked again
    pipe.fit_reheat_leak(data, weeks=[0])
    assert len(tracked) == 1
    pipe.params = base
    # nothing to measure: constant films, or boxes that never reheat
    n = len(calls)
    monkeypatch.setattr(pipe, "_building_or_none",
                        lambda: types.SimpleNamespace(inside_convection="Simple"))
    assert pipe.fit_operating_films(data, weeks=[0]) == {} and len(calls) == n
    assert pipe.identification.operating_films_test is None
    monkeypatch.setattr(pipe, "_building_or_none",
                        lambda: types.SimpleNamespace(inside_convection="TARP"))
    monkeypatch.setattr(pl, "fit_reheat_leak", leak_of([0.2] * p, [0.02] * p))
    dry = dataclasses.replace(data, reheat=np.zeros_like(data.reheat))
    assert pipe.fit_operating_films(dry, weeks=[0]) == {} and len(calls) == n
    with pytest.raises(PipelineError, match="operating_films='always': use 'none' or "
                                            "'natural' or 'auto'"):
        pl.identify_operating_films("always")
    assert pl.identify_operating_films("auto") == "none"
