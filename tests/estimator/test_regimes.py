"""Inside convection regimes: floor and ceiling films switched while a room's boxes reheat
(ModelOptions.inside_convection="regime"), on NREL's 5-zone floor."""

import numpy as np
import pytest
import scipy.linalg as sla
from zonecast.estimator.artifact import load_structure, save_structure
from zonecast.estimator.integrate import ExactStepper, switched_matrix
from zonecast.estimator.model import BilinearModel
from zonecast.estimator.rc.network import (
    CEIL,
    FLOOR,
    REGIME_CEILING,
    REGIME_FLOOR,
    ModelDefinitionError,
    ModelOptions,
    build_structure,
)

ZONES = {"South": ["SPACE1-1"], "East": ["SPACE2-1"], "North": ["SPACE3-1"],
         "West": ["SPACE4-1"], "Core": ["SPACE5-1"]}
BOXES = {f"VAV{i}": f"SPACE{i}-1" for i in range(1, 6)}


def _opts(**kw):
    return ModelOptions(infiltration="none", ground="adiabatic", shading="none", **kw)


@pytest.fixture(scope="module")
def pair(five_zone):
    """(constant, regime) structures with return air (a general generator) and without (a
    symmetric one)."""
    out = {}
    for ret in ("idf", "none"):
        out[ret] = (build_structure(five_zone, ZONES, BOXES, _opts(return_air=ret)),
                    build_structure(five_zone, ZONES, BOXES,
                                    _opts(return_air=ret, inside_convection="regime")))
    return out


def test_unknown_regime_option_says_what_is_allowed():
    with pytest.raises(ModelDefinitionError, match="inside_convection must be"):
        ModelOptions(inside_convection="tarp")


def test_regime_links_are_the_floor_and_ceiling_films_of_rooms_with_boxes(pair):
    plain, st = pair["idf"]
    assert plain.switched == {}
    sw = st.switched
    assert sorted(sw["rooms"]) == sorted(BOXES.values())
    air = {st.labels[i].room for i in st.air_states()}
    rooms_of_links = {st.labels[b].room for _, b, _ in sw["links"]}
    assert rooms_of_links <= air and len(rooms_of_links) == 5
    for (face, room_air, col), p, f in zip(sw["links"], sw["param"], sw["factor"]):
        assert st.labels[room_air].room == sw["rooms"][col]
        assert st.labels[face].kind not in ("room_air", "unmeasured_air")
        assert p in (FLOOR, CEIL)
        assert f == (REGIME_FLOOR if p == FLOOR else REGIME_CEILING)
    # every room has both a floor and a ceiling film switched
    for col in range(5):
        assert set(sw["param"][sw["links"][:, 2] == col]) == {FLOOR, CEIL}
    # the structure is otherwise the same
    assert (plain.A0 != st.A0).nnz == 0
    assert any("inside convection regimes" in n for n in st.notes)


def test_modes_follow_the_boxes_discharge_air(pair):
    m = BilinearModel(pair["idf"][1])
    u = np.full((3, 5), 0.3)
    u[2, 0] = 0.0  # no airflow: no heat from that box
    reheat = np.zeros((3, 5))
    reheat[1, 1] = 5.0   # box 2 reheats: its room's mode
    reheat[1, 2] = 0.5   # below REGIME_RISE
    reheat[2, 0] = 8.0
    modes = m.modes(u, reheat)
    col = {r: i for i, r in enumerate(m.structure.switched["rooms"])}
    assert modes.shape == (3, 5)
    assert modes[0].sum() == 0 and modes[2].sum() == 0
    assert modes[1, col["SPACE2-1"]] == 1 and modes[1].sum() == 1
    assert np.array_equal(m.modes(u[1], reheat[1]), modes[1])
    assert BilinearModel(pair["idf"][0]).modes(u, reheat) is None


def test_switched_films_change_the_conductance_by_the_regime_ratio(pair):
    st = pair["none"][1]
    m = BilinearModel(st)
    u = np.full(5, 0.2)
    mode = np.zeros(5)
    mode[0] = 1.0
    diff = m.system_matrix(u, mode) - m.system_matrix(u)
    theta = m.params.physical
    sw = st.switched
    for (face, air, col), area, p, f in zip(sw["links"], sw["area"], sw["param"], sw["factor"]):
        g = (f - 1.0) * area * theta[p]  # extra conductance [W/K]
        want = g / st.capacity[face] if col == 0 else 0.0
        assert diff[face, air] == pytest.approx(want, rel=1e-12, abs=1e-18)
    # the floor's film weaker, the ceiling's stronger, energy conserved: K stays symmetric
    k = -st.capacity[:, None] * m.system_matrix(u, mode)
    np.testing.assert_allclose(k, k.T, atol=1e-9 * np.abs(k).max())
    lam = np.linalg.eigvals(m.system_matrix(u, mode))
    assert lam.real.max() < 0


@pytest.mark.parametrize("ret", ["idf", "none"])
def test_propagators_equal_the_dense_exponential_in_every_mode(pair, ret):
    m = BilinearModel(pair[ret][1])
    u = np.array([0.1, 0.4, 0.0, 0.3, 0.2])
    for mode in (np.zeros(5), np.array([1.0, 0, 1, 0, 0]), np.ones(5)):
        phi, gam = m._lookup(u, mode)
        want = sla.expm(m.system_matrix(u, mode) * m.step)
        np.testing.assert_allclose(phi, want, atol=1e-10)
        ms = m.system_matrix(u, mode)
        np.testing.assert_allclose(ms @ gam, want - np.eye(m.n), atol=1e-10)


@pytest.mark.parametrize("ret", ["idf", "none"])
def test_exact_stepper_follows_the_modes_step_by_step(pair, ret):
    m = BilinearModel(pair[ret][1])
    rng = np.random.default_rng(4)
    N = 12
    u = rng.uniform(0.05, 0.5, (N, 5))
    reheat = np.where(rng.random((N, 5)) < 0.4, 6.0, 0.0)
    modes = m.modes(u, reheat)
    assert 0 < modes.mean() < 1
    v = np.column_stack([rng.uniform(-5, 10, N), np.full(N, 13.0), rng.uniform(0, 300, (N, 5))])
    x0 = np.full(m.n, 21.0)
    exact = m.simulate(x0, u, v, reheat=reheat, method="exact").x
    eig = m.simulate(x0, u, v, reheat=reheat, method="eig").x
    np.testing.assert_allclose(exact, eig, atol=1e-7)
    # the stepper's single steps equal its run, and both differ from the constant films
    st = ExactStepper(m.structure.A(m.params.physical), m._rooms, m._bxu, m.step,
                      u.max(axis=0), capacity=m.structure.capacity, ret=m._ret,
                      retc=m._retc, switched=m.switched)
    forcing = v @ m.Bv.T + m.params.c_ig @ m.B_ig.T + m.reheat_forcing(u, reheat)
    run = st.run(x0, u, forcing, v[:, 1], modes)
    x = x0
    for k in range(N):
        x = st.step(x, u[k], forcing[k], v[k, 1], modes[k])
        np.testing.assert_array_equal(x, run[k + 1])
    np.testing.assert_allclose(run, exact, atol=1e-9)
    off = st.run(x0, u, forcing, v[:, 1])
    assert np.abs(off - run).max() > 1e-3


def test_no_reheat_is_the_model_with_constant_films(pair):
    plain, st = pair["idf"]
    a, b = BilinearModel(plain), BilinearModel(st)
    rng = np.random.default_rng(1)
    N = 6
    u = rng.uniform(0.05, 0.5, (N, 5))
    v = np.column_stack([rng.uniform(-5, 10, N), np.full(N, 13.0), rng.uniform(0, 300, (N, 5))])
    x0 = np.full(a.n, 20.0)
    # every room in its usual regime: the constant films' model (to the series' tolerance:
    # the switched model's series covers the stiffer regime too, so it has more terms)
    np.testing.assert_allclose(a.simulate(x0, u, v).x, b.simulate(x0, u, v).x, atol=1e-9)
    # and the kernel with switched links all off is the kernel without them, bit for bit
    A = plain.A(a.params.physical)
    st_plain = ExactStepper(A, a._rooms, a._bxu, a.step, u.max(axis=0), ret=a._ret,
                            retc=a._retc)
    st_sw = ExactStepper(A, a._rooms, a._bxu, a.step, u.max(axis=0), ret=a._ret,
                         retc=a._retc, switched=b.switched)
    st_sw.r, st_sw.coef = st_plain.r, st_plain.coef  # the same series
    f = v @ a.Bv.T
    np.testing.assert_array_equal(st_plain.run(x0, u, f, v[:, 1]),
                                  st_sw.run(x0, u, f, v[:, 1], np.zeros((N, b.n_modes))))


def test_switched_matrix_by_default_is_the_stiffest_case(pair):
    m = BilinearModel(pair["none"][1])
    swi, swg = m.switched
    stiff = switched_matrix(m.n, swi, swg).toarray()
    pos = swg[:, 0] > 0  # the ceilings' films, stronger in the reheat regime
    assert pos.any() and not pos.all()
    want = switched_matrix(m.n, swi[pos], swg[pos], np.ones(m.n_modes)).toarray()
    np.testing.assert_array_equal(stiff, want)


def test_structure_file_keeps_the_switched_links(pair, tmp_path):
    st = pair["idf"][1]
    back, _ = load_structure(save_structure(tmp_path / "s.npz", st, {"SPACE1-1": 1.0}))
    assert back.options.inside_convection == "regime"
    for key in ("links", "area", "param", "factor"):
        np.testing.assert_array_equal(back.switched[key], st.switched[key])
    assert back.switched["rooms"] == st.switched["rooms"]
    plain, _ = load_structure(save_structure(tmp_path / "p.npz", pair["idf"][0],
                                             {"SPACE1-1": 1.0}))
    assert plain.switched == {}


def test_the_online_estimator_refuses_a_regime_model_with_what_to_do(pair):
    from zonecast.estimator.streaming import OnlineEstimator

    class Bundle:
        model = BilinearModel(pair["idf"][1])

    with pytest.raises(ValueError, match="inside_convection='constant'"):
        OnlineEstimator(Bundle())


def test_identification_fast_path_follows_the_modes_and_the_parameters(pair):
    """The fit's compiled runs (identify._Problem) switch the films as the model does, with
    the switched conductances following theta (γ_floor, γ_ceil)."""
    import pandas as pd
    from zonecast.estimator.dataset import ModelData
    from zonecast.estimator.identify import _Problem

    st = pair["idf"][1]
    rng = np.random.default_rng(7)
    N = 16
    times = pd.date_range("2015-04-18 08:00", periods=N, freq="15min", tz="UTC")
    u = rng.uniform(0.05, 0.5, (N, 5))
    reheat = np.where(rng.random((N, 5)) < 0.4, 6.0, 0.0)
    v = np.column_stack([rng.uniform(-5, 10, N), np.full(N, 13.0), rng.uniform(0, 300, (N, 5))])
    data = ModelData(times, u, v, np.full((N, 5), 21.0), list(st.zones), list(st.boxes),
                     [(0, N)], np.zeros(N, bool), "UTC", reheat=reheat)
    base = BilinearModel(st)
    theta = base.params.values.copy()
    names = base.params.param_names
    theta[names.index("gamma_ceil")] *= 3.0  # the switched conductances follow theta
    model = base.with_params(theta)
    x0 = np.full(model.n, 21.0)
    prob = _Problem(model, data, [(0, N - 1)], [x0])
    got = prob.simulate(theta)[0]
    want = model.simulate(x0, u[:N - 1], v[:N - 1], reheat=reheat[:N - 1]).y[1:]
    np.testing.assert_allclose(got, want, atol=1e-8)
    # without the modes the runs differ: the switch is in the fast path
    plain = BilinearModel(pair["idf"][0], model.params)
    off = plain.simulate(x0, u[:N - 1], v[:N - 1], reheat=reheat[:N - 1]).y[1:]
    assert np.abs(off - got).max() > 1e-4
