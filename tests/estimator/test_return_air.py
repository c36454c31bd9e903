"""Return air through a return plenum (NREL's 5-zone: five VAV boxes return into PLENUM-1)."""

import numpy as np
import pytest
import scipy.linalg as sla
from zonecast.estimator.artifact import load_structure, save_structure
from zonecast.estimator.integrate import ExactStepper, simulate_exact
from zonecast.estimator.model import BilinearModel
from zonecast.estimator.rc.network import ModelOptions, build_structure
from zonecast.estimator.rc.parameters import ParameterSet

ZONES = {"South": ["SPACE1-1"], "East": ["SPACE2-1"], "North": ["SPACE3-1"],
         "West": ["SPACE4-1"], "Core": ["SPACE5-1"]}
BOXES = {f"VAV{i}": f"SPACE{i}-1" for i in range(1, 6)}
OPTS = ModelOptions(infiltration="none", ground="adiabatic", shading="none")


@pytest.fixture(scope="module")
def structures(five_zone):
    return (build_structure(five_zone, ZONES, BOXES, OPTS),
            build_structure(five_zone, ZONES, BOXES,
                            ModelOptions(infiltration="none", ground="adiabatic",
                                         shading="none", return_air="none")))


def test_the_idf_return_plenum_is_read(five_zone):
    assert five_zone.return_plenum == {f"SPACE{i}-1": "PLENUM-1" for i in range(1, 6)}


def test_structure_routes_every_box_into_the_plenum(structures):
    st, plain = structures
    plenum = st.rooms.index("PLENUM-1")
    ret, coef = st.returns
    assert ret.tolist() == [plenum] * 5
    assert coef == pytest.approx(st.cp_air / st.capacity[plenum])
    assert plain.return_of_box is None and (plain.returns[0] == -1).all()
    # the same conductances: return air is an airflow term only
    assert (st.A0 != plain.A0).nnz == 0


def _inputs(n_steps=96, seed=3):
    rng = np.random.default_rng(seed)
    u = np.clip(0.3 + 0.25 * rng.standard_normal((n_steps, 5)), 0.0, 0.9)
    hours = np.arange(n_steps) / 4.0
    v = np.column_stack([8 + 6 * np.sin(2 * np.pi * hours / 24), np.full(n_steps, 13.0),
                         *[np.clip(400 * np.sin(2 * np.pi * (hours - 6) / 24), 0, None)] * 5])
    return u, v


def test_system_matrix_is_metzler_and_conserves_the_return_air(structures):
    st, _ = structures
    m = BilinearModel(st, ParameterSet(list(ZONES)))
    u = np.full(5, 0.4)
    A = m.system_matrix(u)
    off = A - np.diag(np.diag(A))
    assert (off >= -1e-15).all()
    assert np.linalg.eigvals(A).real.max() < 0
    # heat carried by each box: the room's air leaves at x_room (-c_p u x_room at the room,
    # with the supply air's c_p u Ts as an input) and arrives in the plenum: the plenum's
    # column sum of c_p-weighted airflow terms is zero
    plenum = st.rooms.index("PLENUM-1")
    flow = (m.capacity if hasattr(m, "capacity") else st.capacity)[:, None] * \
        (A - m.system_matrix(np.zeros(5)))
    assert flow[plenum, :].sum() == pytest.approx(0.0, abs=1e-9)
    rooms = st.room_of_box
    assert flow[rooms, rooms] == pytest.approx(-st.cp_air * u)
    assert flow[plenum, rooms] == pytest.approx(st.cp_air * u)


def test_exact_stepper_equals_the_dense_propagators_with_returns(structures):
    st, _ = structures
    m = BilinearModel(st, ParameterSet(list(ZONES)))
    u, v = _inputs()
    x0 = np.full(m.n, 21.0)
    a = m.simulate(x0, u, v, method="exact")
    b = m.simulate(x0, u, v, method="eig")
    np.testing.assert_allclose(a.x, b.x, rtol=0, atol=1e-8)
    st_ = ExactStepper(st.A(m.params.physical), m._rooms, m._bxu, m.step, u.max(axis=0),
                       capacity=st.capacity, ret=m._ret, retc=m._retc)
    forcing = v @ m.Bv.T + m.params.c_ig @ m.B_ig.T
    x = x0
    for k in range(len(u)):
        x = st_.step(x, u[k], forcing[k], v[k, 1])
    np.testing.assert_allclose(x, a.x[-1], rtol=0, atol=1e-8)
    xs = simulate_exact(st.A(m.params.physical), m._rooms, m._bxu, x0, u, forcing, v[:, 1],
                        m.step, capacity=st.capacity, ret=m._ret, retc=m._retc)
    np.testing.assert_allclose(xs, a.x, rtol=0, atol=1e-8)


def _continuous(m, x0, u, v, h, substeps):
    """The continuous model with return air taken exactly, by dense exponentials."""
    n = m.n
    x = np.asarray(x0, float)
    out = [x]
    for k in range(len(u)):
        M = np.zeros((n + 1, n + 1))
        M[:n, :n] = m.system_matrix(u[k])
        M[:n, n] = m.input_matrix(u[k]) @ v[k] + m.B_ig @ m.params.c_ig
        E = sla.expm(M * h / substeps)
        for _ in range(substeps):
            x = (E @ np.append(x, 1.0))[:n]
        out.append(x)
    return np.array(out)


def test_steps_equal_the_continuous_model_with_return_air(structures):
    """Both steppers (the Chebyshev kernel and the dense eigendecomposition) take the return
    air exactly: they equal the continuous model's zero-order-hold solution by dense
    exponentials of the non-symmetric generator, also at large airflows."""
    st, _ = structures
    u, v = _inputs(48)
    m = BilinearModel(st, ParameterSet(list(ZONES)))
    for scale in (1.0, 4.0):
        x0 = np.full(m.n, 21.0)
        ref = _continuous(m, x0, scale * u, v, m.step, 1)
        for method in ("exact", "eig"):
            got = m.simulate(x0, scale * u, v, method=method).x
            np.testing.assert_allclose(got, ref, rtol=0, atol=1e-7)
    lam = np.linalg.eigvals(m.system_matrix(4 * u.max(axis=0)))
    assert lam.real.max() < 0


def test_steady_state_plenum_balances_return_air_and_conduction(structures):
    st, plain = structures
    u, v = np.full(5, 0.5), np.array([5.0, 13.0, 0, 0, 0, 0, 0])
    for s in (st, plain):
        m = BilinearModel(s, ParameterSet(list(ZONES)))
        x = m.steady_state(u, v)
        assert np.abs(m.system_matrix(u) @ x + m.input_matrix(u) @ v
                      + m.B_ig @ m.params.c_ig).max() < 1e-9
    hot = BilinearModel(st, ParameterSet(list(ZONES))).steady_state(u, v)
    cold = BilinearModel(plain, ParameterSet(list(ZONES))).steady_state(u, v)
    p = st.rooms.index("PLENUM-1")
    # the rooms' return air warms the plenum above the conduction-only one
    assert hot[p] > cold[p] + 0.1


def test_structure_file_keeps_the_return_paths(structures, tmp_path):
    st, plain = structures
    back, _ = load_structure(save_structure(tmp_path / "s.npz", st, {"SPACE1-1": 1.0}))
    assert back.return_of_box.tolist() == st.return_of_box.tolist()
    assert back.options.return_air == "idf"
    back, _ = load_structure(save_structure(tmp_path / "p.npz", plain, {"SPACE1-1": 1.0}))
    assert back.return_of_box is None


def test_general_propagators_equal_the_eigendecomposition(structures):
    """Phi = expm(M h), Gamma = M^-1 (Phi - I) (the fast path) equal the propagators of the
    eigendecomposition; a singular M (an isolated state, eigenvalue 0) takes the
    eigendecomposition, whose Gamma is h on that state instead of a division by zero."""
    st, _ = structures
    m = BilinearModel(st, ParameterSet(list(ZONES)))
    u, _ = _inputs(4)
    phi, gam = m._propagators_general(u)
    phi_e, gam_e = m._propagators_eig(u)
    np.testing.assert_allclose(phi, phi_e, rtol=0, atol=1e-12)
    np.testing.assert_allclose(gam, gam_e, rtol=0, atol=1e-10 * np.abs(gam_e).max())
    regular = m.system_matrix

    def isolated(row):
        M = regular(row).copy()
        M[0, :] = 0.0
        M[:, 0] = 0.0
        return M

    m.system_matrix = isolated
    phi, gam = m._propagators_general(u[:1])
    assert np.all(np.isfinite(gam))
    assert phi[0, 0, 0] == pytest.approx(1.0) and gam[0, 0, 0] == pytest.approx(m.step)


def test_stepper_propagator_with_return_air(structures):
    """The series' dense propagator (identification's x(0) filter) equals the propagators of
    the non-symmetric generator with return air."""
    st, _ = structures
    m = BilinearModel(st, ParameterSet(list(ZONES)))
    u, _ = _inputs(4)
    stepper = ExactStepper(st.A(m.params.physical), m._rooms, m._bxu, m.step, u.max(axis=0),
                           capacity=st.capacity, ret=m._ret, retc=m._retc)
    for row in u:
        np.testing.assert_allclose(stepper.propagator(row), m._propagators_eig(row[None])[0][0],
                                   rtol=0, atol=1e-10)
