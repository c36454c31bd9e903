"""Outside films of exterior faces from the site's wind (estimator/outside_films.py)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from zonecast.estimator import outside_films as of


def test_doe2_convection_is_the_engineering_references_form():
    """h = h_n + R_f (sqrt(h_n^2 + (a V^b)^2) - h_n), restated by hand for a windward and a
    leeward vertical face and a roof; with no wind only the natural part is left."""
    cube = 5.0 ** (1 / 3)
    hn_wall = 1.31 * cube
    forced = 3.26 * 3.0 ** 0.89
    want = hn_wall + 1.52 * (math.hypot(hn_wall, forced) - hn_wall)
    assert of.doe2_convection(3.0, "MediumRough", 90.0, True) == pytest.approx(want)
    lee = 3.55 * 3.0 ** 0.617
    want = hn_wall + 2.17 * (math.hypot(hn_wall, lee) - hn_wall)
    assert of.doe2_convection(3.0, "VeryRough", 90.0, False) == pytest.approx(want)
    hn_roof = 0.5 * (9.482 * cube / 6.238 + 1.810 * cube / 2.382)
    assert of.natural_convection(0.0) == pytest.approx(hn_roof)
    assert of.doe2_convection(0.0, "Smooth", 0.0) == pytest.approx(hn_roof)
    # MoWiTT is the smooth-glass form, without the roughness multiplier
    assert of.mowitt_convection(3.0, 90.0, True) == pytest.approx(math.hypot(hn_wall, forced))


def test_simple_combined_and_long_wave():
    """SimpleCombined: D + E V + F V^2 by roughness; the long-wave film 4 eps sigma T^3
    (4.6 W/m2K at 10 degC for eps 0.9)."""
    assert of.simple_combined_film(2.0, "Rough") == pytest.approx(12.49 + 4.065 * 2 + 0.028 * 4)
    assert of.simple_combined_film(0.0, "VerySmooth") == pytest.approx(8.23)
    assert of.long_wave_film(10.0) == pytest.approx(4 * 0.9 * 5.670374419e-8 * 283.15 ** 3)
    assert 4.5 < of.long_wave_film(10.0) < 4.8
    with pytest.raises(ValueError, match="is not one of EnergyPlus's VeryRough"):
        of.simple_combined_film(1.0, "Bumpy")
    with pytest.raises(ValueError, match="Bumpy"):
        of.doe2_convection(1.0, "Bumpy", 90.0)


@settings(max_examples=40, deadline=None)
@given(v=st.floats(0.0, 20.0), dv=st.floats(0.01, 5.0), tilt=st.floats(0.0, 180.0),
       rough=st.sampled_from(sorted(of.ROUGHNESS_MULTIPLIER)), ww=st.booleans())
def test_films_grow_with_the_wind_and_the_roughness(v, dv, tilt, rough, ww):
    """Physics: more wind never lowers a film; a rougher face never has a lower one; every
    film is at least the natural convection."""
    h = of.doe2_convection(v, rough, tilt, ww)
    assert of.doe2_convection(v + dv, rough, tilt, ww) >= h - 1e-12
    assert h >= of.natural_convection(tilt) - 1e-12
    assert of.doe2_convection(v, "VeryRough", tilt, ww) >= h - 1e-12
    assert of.simple_combined_film(v + dv, rough) >= of.simple_combined_film(v, rough) - 1e-12


def test_windward_faces():
    """A wall is windward within 100 degrees of its normal; a roof always."""
    wind = np.array([180.0, 270.0, 290.0, 0.0])
    assert of.windward(wind, 180.0, 90.0).tolist() == [True, True, False, False]
    assert of.windward(wind, 180.0, 10.0).all()


def test_epw_wind_reads_speed_direction_and_air(tmp_path):
    """The EPW's fields 22, 21 and 7; missing values (999, 99.9) left out; a file without
    data rows is refused with what to give."""
    head = [f"HEADER{i}\n" for i in range(8)]

    def row(t, d, v):
        f = ["2015", "1", "1", "1", "0", "?", str(t)] + ["0"] * 13 + [str(d), str(v)] + ["0"] * 13
        return ",".join(f) + "\n"

    p = tmp_path / "w.epw"
    p.write_text("".join(head) + row(5.0, 90, 3.0) + row(6.0, 999, 4.0) + row(7.0, 180, 2.0))
    speed, direction, air = of.epw_wind(p)
    assert speed.tolist() == [3.0, 2.0]
    assert direction.tolist() == [90.0, 180.0]
    assert air.tolist() == [5.0, 7.0]
    empty = tmp_path / "e.epw"
    empty.write_text("".join(head))
    with pytest.raises(ValueError, match="give an EPW weather file"):
        of.epw_wind(empty)


def test_climate_films_match_energyplus_own_dry_films(five_zone, small_office):
    """Against EnergyPlus's dry-row means of the runs of docs/benchmarks.md "Outside films
    from the site's wind" (Chicago O'Hare TMY3, the EPW nearest to both inputs): the 5-zone's
    SimpleCombined roof 18.17 W/m2K, the small office's DOE-2 attic roofs 8.76-9.09
    convection + 4.4 long-wave. Each within 5 %."""
    assert five_zone.outside_convection == "SimpleCombined"
    assert five_zone.weather_file is not None and "Chicago" in five_zone.weather_file.name
    assert of.climate_films(five_zone, ["TOP-1"])["TOP-1"] == pytest.approx(18.17, rel=0.05)
    roofs = [n for n, s in small_office.surfaces.items()
             if s.boundary == "Outdoors" and s.surface_type == "Roof"]
    films = of.climate_films(small_office, roofs)
    assert len(films) == 4
    for h in films.values():
        assert h == pytest.approx(8.9 + 4.4, rel=0.05)
    # every exterior face by default; walls lower than the 5-zone's rough roof
    every = of.climate_films(five_zone)
    assert set(every) == {n for n, s in five_zone.surfaces.items() if s.boundary == "Outdoors"}
    with pytest.raises(ValueError, match="give the site's weather_file"):
        of.climate_films(dataclasses.replace(five_zone, weather_file=None))


def test_climate_films_take_doe2_for_tarp_with_a_note(five_zone):
    """TARP (and the adaptive algorithm) are taken as DOE-2, said in the notes; MoWiTT
    has no roughness multiplier, so a rough face's film is lower than DOE-2's."""
    b = dataclasses.replace(five_zone, outside_convection="TARP", notes=[])
    doe2 = dataclasses.replace(five_zone, outside_convection="DOE-2", notes=[])
    mowitt = dataclasses.replace(five_zone, outside_convection="MoWiTT", notes=[])
    assert of.climate_films(b, ["TOP-1"]) == of.climate_films(doe2, ["TOP-1"])
    assert any("taken as DOE-2's" in n for n in b.notes) and not doe2.notes
    assert of.climate_films(mowitt, ["TOP-1"])["TOP-1"] < of.climate_films(doe2, ["TOP-1"])["TOP-1"]


def test_roof_film_prior_is_the_roofs_climate_film(small_office, five_zone):
    """gamma_roof's prior (``roof_exterior="own"``): the roofs' area-weighted climate film
    with gamma_EW's relative spread (12 / 25), log-normal like the other films; the
    handbook's 25 +- 12 without a weather file, saying why; no gamma_roof prior for a
    parameter set without the parameter."""
    from zonecast.estimator.priors import building_priors, roof_film_prior
    from zonecast.estimator.rc.parameters import ParameterSet

    roofs = {n: s.area for n, s in small_office.surfaces.items()
             if s.boundary == "Outdoors" and s.surface_type == "Roof"}
    films = of.climate_films(small_office, list(roofs))
    want = sum(films[n] * a for n, a in roofs.items()) / sum(roofs.values())
    mean, sd, source = roof_film_prior(small_office)
    assert mean == pytest.approx(want, rel=1e-12) and sd == pytest.approx(want * 12 / 25)
    assert "climate film" in source
    mean, sd, source = roof_film_prior(dataclasses.replace(five_zone, weather_file=None))
    assert (mean, sd) == (25.0, 12.0) and "no climate film" in source
    own = ParameterSet(["a"], extra=("gamma_roof",))
    pri = building_priors(own, small_office, positive="log")
    assert pri["gamma_roof"].log and pri["gamma_roof"].mean == pytest.approx(want, rel=1e-12)
    assert list(pri) == own.param_names
    assert "gamma_roof" not in building_priors(ParameterSet(["a"]), small_office)


def test_sunlit_films_are_the_sol_air_balance_of_each_sunny_hour():
    """One sunny hour: the returned films satisfy the balance they were iterated to,
    dT = (a I - h_r (T_a - T_sky)) / (h_c + h_r) with h_c DOE-2's at dT (heat flowing up)
    and h_r = 4 eps sigma T_m^3; two hours weigh by the absorbed sun; a darker face runs
    hotter, so its films are larger; no sun at all is an error."""
    sigma = 5.670374419e-8
    t_sky = 263.15
    ir = sigma * t_sky ** 4
    args = {"tilt": 0.0, "azimuth": 0.0, "roughness": "MediumRough", "emissivity": 0.9}
    hc, hr = of.sunlit_film_parts([3.0], [180.0], [20.0], [ir], [800.0], absorptance=0.7,
                                  iterations=30, **args)
    dt = (0.7 * 800.0 - hr * (293.15 - t_sky)) / (hc + hr)
    assert dt > 15.0
    assert hc == pytest.approx(float(of.doe2_convection(3.0, "MediumRough", 0.0, True, dt,
                                                        "up")), rel=1e-6)
    assert hr == pytest.approx(4 * 0.9 * sigma * (0.5 * (293.15 + dt + t_sky)) ** 3, rel=1e-6)
    dark = of.sunlit_film_parts([3.0], [180.0], [20.0], [ir], [800.0], absorptance=0.95,
                                iterations=30, **args)
    assert dark[0] > hc and dark[1] > hr
    # a night hour (no sun) carries no weight; two sunny hours weigh by a I
    two = of.sunlit_film_parts([3.0, 3.0, 3.0], [180.0] * 3, [20.0] * 3, [ir] * 3,
                               [800.0, 0.0, 200.0], absorptance=0.7, iterations=30, **args)
    low = of.sunlit_film_parts([3.0], [180.0], [20.0], [ir], [200.0], absorptance=0.7,
                               iterations=30, **args)
    assert two[0] == pytest.approx((800 * hc + 200 * low[0]) / 1000, rel=1e-9)
    with pytest.raises(ValueError, match="no sun"):
        of.sunlit_film_parts([3.0], [180.0], [20.0], [ir], [0.0], absorptance=0.7, **args)
