"""Fast exact stepping of the bilinear model with the inputs held over each step.

Over step k the airflows u(k) and disturbances v(k) are constant, so the model of paper
eq:ct_model is a linear ODE  dx/dt = A(u_k) x + b_k,  A(u) = A + sum_j B_xu_j u_j,  whose
exact solution over the step is  [x(k+1); 1] = exp(M_k h) [x(k); 1]  with the augmented
matrix  M_k = [[A(u_k), b_k], [0, 0]].

Two facts make this cheap without a dense matrix exponential per distinct airflow:

* A is sparse (rooms couple only through wall elements) and only its room-air diagonal
  depends on u (the HVAC term, paper eq:q_hvac);
* A(u) = diag(1/cap) K(u) with K symmetric negative semidefinite, so its eigenvalues are
  real and lie in [-L, 0] with L from Gershgorin's theorem (A is diagonally dominant:
  L = 2 max_i |a_ii|); the augmented M_k adds only the eigenvalue 0.

exp(M h) is therefore applied to the vector with a Chebyshev expansion on [-L h, 0]:
exp(x) = e^{-r} (I_0(r) + 2 sum_k I_k(r) T_k(1 + x / r)), r = L h / 2, whose coefficients
(modified Bessel functions) fall below 1e-11 of the first after about r + 4 sqrt(r)
terms: ~24 sparse products per step for the virtual building. The result equals the exact
zero-order-hold solution to round-off (tested against dense matrix exponentials).

Why hand-written: scipy's ``expm_multiply`` (Taylor-based, general matrices) needs about
four times more products here and pays Python overhead per product (~1 ms per step);
this kernel is compiled with numba. The Chebyshev approach for symmetric generators is
textbook (e.g. Tal-Ezer and Kosloff 1984; Moler and Van Loan, "Nineteen dubious ways").
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import ArpackNoConvergence, eigsh
from scipy.special import ive

try:  # numba is a dependency; keep a pure-Python fallback for platforms without it
    from numba import njit
except ImportError:  # pragma: no cover - exercised only without numba
    def njit(*args, **kwargs):
        def wrap(f):
            return f
        return wrap if not (args and callable(args[0])) else args[0]

#: truncation of the Chebyshev series (scaled Bessel coefficients below this are dropped)
TOL = 1e-11


def return_rho(A, rooms, bxu, ret, retc, u_max, L: float) -> float:
    """Bernstein-ellipse parameter rho >= 1 enclosing the eigenvalues of A(u) on the
    Chebyshev interval [-L, 0] (scaled to [-1, 1]) for airflows up to ``u_max``: 1 when they
    are real (a symmetric generator), more when return air or one-way couplings
    (:func:`_one_way`) make A(u) non-symmetric and some leave the real axis. From the dense
    eigenvalues at ``u_max`` and at half of it, with a margin of 50 % on rho - 1. A face that
    follows a neighbour it is already linked to (a two-node adiabatic element) keeps the
    pattern symmetric and the spectrum real (a diagonal scaling of that face alone makes the
    pair symmetric), so the pattern is enough to tell."""
    ret = np.asarray(ret)
    A = sp.csr_matrix(A, dtype=float)
    if L <= 0 or not (np.any(ret >= 0) or _one_way(A)):
        return 1.0
    rho = 1.0
    for f in (1.0, 0.5):
        u = f * np.asarray(u_max, dtype=float)
        M = A.toarray()
        np.add.at(M, (rooms, rooms), np.asarray(bxu) * u)
        has = ret >= 0
        g = np.asarray(retc)[has] * u[has]
        np.add.at(M, (ret[has], np.asarray(rooms)[has]), g)
        np.add.at(M, (ret[has], ret[has]), -g)
        z = 1.0 + 2.0 * np.linalg.eigvals(M) / L
        w = z + np.sqrt(z * z - 1.0 + 0j)
        rho = max(rho, float(np.max(np.maximum(np.abs(w), 1.0 / np.maximum(np.abs(w), 1e-300)))))
    return 1.0 + 1.5 * (rho - 1.0)


def _one_way(A: sp.csr_matrix) -> bool:
    """Whether some state is driven by another that it does not drive back (a face that
    follows another, ``ModelOptions.adiabatic="mirror"``): a coupling pattern that is not
    symmetric, whose eigenvalues may leave the real axis."""
    p = (A != 0).astype(np.int8)
    p.setdiag(0)
    p.eliminate_zeros()
    return (p != p.T).nnz > 0


def chebyshev_coefficients(r: float, tol: float = TOL, rho: float = 1.0) -> np.ndarray:
    """Coefficients c_k = e^{-r} I_k(r) (c_0 once, the others doubled) of exp on [-2r, 0];
    with ``rho`` > 1, enough terms for eigenvalues inside the Bernstein ellipse of that
    parameter (c_k rho^k below ``tol`` c_0)."""
    kmax = int(rho * r + 6.0 * np.sqrt(rho * r + 1.0) + 20.0 * rho)
    c = ive(np.arange(kmax + 1), r)
    keep = np.flatnonzero(c * rho ** np.arange(kmax + 1) > tol * c[0])
    c = c[: keep[-1] + 1].copy()
    c[1:] *= 2.0
    return c


@njit(cache=True, nogil=True)
def _return_terms(rooms, ret, retc, u, swi, swg, mode, scale, dd):
    # the plenums' outflow added to the diagonal dd (in place) and the rooms' inflow into
    # each plenum row as CSR lists: row pointers cnt, source rooms rr, scaled gains rg; then
    # the switched links active at this step (swi[e] = state a, state b, mode column; swg[e]
    # = the link's extra conductance over C_a and over C_b [1/s] at mode 1): their diagonal
    # in dd and their two off-diagonal entries in the same lists. Without switched links the
    # lists, and so the arithmetic, are those of the return air alone.
    n = dd.shape[0]
    cnt = np.zeros(n + 1, dtype=np.int64)
    m = 0
    for j in range(ret.shape[0]):
        p = ret[j]
        if p >= 0:
            dd[p] -= retc[j] * u[j]
            cnt[p + 1] += 1
            m += 1
    for e in range(swi.shape[0]):
        w = mode[swi[e, 2]]
        if w != 0.0:
            a = swi[e, 0]
            b = swi[e, 1]
            dd[a] -= swg[e, 0] * w
            dd[b] -= swg[e, 1] * w
            cnt[a + 1] += 1
            cnt[b + 1] += 1
            m += 2
    for i in range(n):
        cnt[i + 1] += cnt[i]
    rr = np.empty(m, dtype=np.int64)
    rg = np.empty(m)
    fill = cnt[:n].copy()
    for j in range(ret.shape[0]):
        p = ret[j]
        if p >= 0:
            rr[fill[p]] = rooms[j]
            rg[fill[p]] = retc[j] * u[j] * scale
            fill[p] += 1
    for e in range(swi.shape[0]):
        w = mode[swi[e, 2]]
        if w != 0.0:
            a = swi[e, 0]
            b = swi[e, 1]
            rr[fill[a]] = b
            rg[fill[a]] = swg[e, 0] * w * scale
            fill[a] += 1
            rr[fill[b]] = a
            rg[fill[b]] = swg[e, 1] * w * scale
            fill[b] += 1
    return cnt, rr, rg


@njit(cache=True, nogil=True)
def _step(indptr, indices, data, rooms, bxu, ret, retc, swi, swg, x, u, mode, b_fixed, ts, h, r,
          coef, out):
    n = x.shape[0]
    # t = 1 + M h / r acting on [w; c] (the augmented component c is 1 for every T_k);
    # the scaled generator (A + diag(dd)) h / r and forcing b h / r are formed once
    scale = h / r
    dd = np.zeros(n)
    for j in range(rooms.shape[0]):
        dd[rooms[j]] += bxu[j] * u[j]            # <= 0 on room-air rows: -c_p u / C
    b = np.empty(n)
    diag = np.empty(n)
    for i in range(n):
        b[i] = (b_fixed[i] - dd[i] * ts) * scale  # + c_p u Ts / C (paper eq:q_hvac)
    # return air into a plenum: c_p u_j (x_room - x_plenum) / C_plenum: the plenum's own air
    # leaving (diagonal) and the room's air entering (off-diagonal entries of the plenum's
    # row, per step: cnt/rr/rg in CSR form, added inside each row's product; empty without
    # return air, which leaves the arithmetic of the symmetric model unchanged)
    cnt, rr, rg = _return_terms(rooms, ret, retc, u, swi, swg, mode, scale, dd)
    for i in range(n):
        diag[i] = 1.0 + dd[i] * scale
    d = data * scale
    w_prev = np.empty(n)
    w_cur = np.empty(n)
    w_next = np.empty(n)
    for i in range(n):
        w_prev[i] = x[i]
        out[i] = coef[0] * x[i]
    for i in range(n):
        acc = diag[i] * w_prev[i] + b[i]
        for q in range(indptr[i], indptr[i + 1]):
            acc += d[q] * w_prev[indices[q]]
        for e in range(cnt[i], cnt[i + 1]):
            acc += rg[e] * w_prev[rr[e]]
        w_cur[i] = acc
        out[i] += coef[1] * acc
    for k in range(2, coef.shape[0]):
        ck = coef[k]
        for i in range(n):
            acc = diag[i] * w_cur[i] + b[i]
            for q in range(indptr[i], indptr[i + 1]):
                acc += d[q] * w_cur[indices[q]]
            for e in range(cnt[i], cnt[i + 1]):
                acc += rg[e] * w_cur[rr[e]]
            nxt = 2.0 * acc - w_prev[i]
            w_next[i] = nxt
            out[i] += ck * nxt
        w_prev, w_cur, w_next = w_cur, w_next, w_prev


@njit(cache=True, nogil=True)
def _block(indptr, indices, data, rooms, bxu, ret, retc, swi, swg, u, mode, X, bcols, sk, ts, h, r,
           coef, out):
    # out = one step of _step for m states at once: column c starts at X[:, c] and is forced
    # by bcols[:, c] * sk[c] (plus the supply-air term with ts); the series of _step with the
    # same arithmetic per column, the rows' columns contiguous (the inner loops vectorise)
    n, m = X.shape
    scale = h / r
    dd = np.zeros(n)
    for j in range(rooms.shape[0]):
        dd[rooms[j]] += bxu[j] * u[j]
    b = np.empty((n, m))
    for i in range(n):
        for c in range(m):
            b[i, c] = (bcols[i, c] * sk[c] - dd[i] * ts) * scale
    cnt, rr, rg = _return_terms(rooms, ret, retc, u, swi, swg, mode, scale, dd)
    diag = np.empty(n)
    for i in range(n):
        diag[i] = 1.0 + dd[i] * scale
    d = data * scale
    w_prev = X.copy()
    w_cur = np.empty((n, m))
    w_next = np.empty((n, m))
    row = np.empty(m)
    for i in range(n):
        for c in range(m):
            out[i, c] = coef[0] * X[i, c]
    for k in range(1, coef.shape[0]):
        ck = coef[k]
        for i in range(n):
            di = diag[i]
            for c in range(m):
                row[c] = di * w_prev[i, c] + b[i, c]
            for q in range(indptr[i], indptr[i + 1]):
                dq = d[q]
                src = indices[q]
                for c in range(m):
                    row[c] += dq * w_prev[src, c]
            for e in range(cnt[i], cnt[i + 1]):
                g = rg[e]
                src = rr[e]
                for c in range(m):
                    row[c] += g * w_prev[src, c]
            if k == 1:
                for c in range(m):
                    w_next[i, c] = row[c]
                    out[i, c] += ck * row[c]
            else:
                for c in range(m):
                    nxt = 2.0 * row[c] - w_cur[i, c]
                    w_next[i, c] = nxt
                    out[i, c] += ck * nxt
        # after term k: w_prev holds T_k, w_cur T_(k-1), w_next is free
        w_cur, w_prev, w_next = w_prev, w_next, w_cur


@njit(cache=True, nogil=True)
def _run_block(indptr, indices, data, rooms, bxu, ret, retc, swi, swg, X0, u, modes, bcols, s, ts,
               h, r, coef, xs):
    xs[0] = X0
    for k in range(u.shape[0]):
        _block(indptr, indices, data, rooms, bxu, ret, retc, swi, swg, u[k], modes[k], xs[k],
               bcols, s[k], ts[k], h, r, coef, xs[k + 1])


@njit(cache=True, nogil=True)
def _columns(indptr, indices, data, rooms, bxu, ret, retc, swi, swg, u, mode, B, h, r, coef, out):
    # out[:, j] = Gamma B[:, j]: the response after one step of a zero state to the unit
    # forcing B[:, j] held over the step (supply-temperature term off)
    n = B.shape[0]
    zero = np.zeros(n)
    col = np.empty(n)
    res = np.empty(n)
    for j in range(B.shape[1]):
        for i in range(n):
            col[i] = B[i, j]
        _step(indptr, indices, data, rooms, bxu, ret, retc, swi, swg, zero, u, mode, col, 0.0, h, r,
              coef, res)
        for i in range(n):
            out[i, j] = res[i]


@njit(cache=True, nogil=True)
def _run(indptr, indices, data, rooms, bxu, ret, retc, swi, swg, x0, u, modes, b_fixed, ts, h, r,
         coef, xs):
    xs[0] = x0
    for k in range(u.shape[0]):
        _step(indptr, indices, data, rooms, bxu, ret, retc, swi, swg, xs[k], u[k], modes[k],
              b_fixed[k], ts[k], h, r, coef, xs[k + 1])


def _no_returns(n_boxes: int) -> tuple[np.ndarray, np.ndarray]:
    return np.full(n_boxes, -1, dtype=np.int64), np.zeros(n_boxes)


def _returns(ret, retc, n_boxes: int) -> tuple[np.ndarray, np.ndarray]:
    if ret is None:
        return _no_returns(n_boxes)
    return np.ascontiguousarray(ret, dtype=np.int64), np.ascontiguousarray(retc, dtype=float)


def no_switches() -> tuple[np.ndarray, np.ndarray]:
    """Empty switched links (:class:`ExactStepper`'s ``switched``): swi (0, 3), swg (0, 2)."""
    return np.zeros((0, 3), dtype=np.int64), np.zeros((0, 2))


def _switches(switched) -> tuple[np.ndarray, np.ndarray]:
    if switched is None:
        return no_switches()
    swi, swg = switched
    swi = np.ascontiguousarray(np.reshape(swi, (-1, 3)), dtype=np.int64)
    swg = np.ascontiguousarray(np.reshape(swg, (-1, 2)), dtype=float)
    if len(swi) != len(swg):
        raise ValueError("switched links: one row of gains per row of indices")
    if not np.isfinite(swg).all():
        raise ValueError("switched links: gains must be finite")
    return swi, swg


def switched_matrix(n: int, swi: np.ndarray, swg: np.ndarray,
                    mode: np.ndarray | None = None) -> sp.csr_matrix:
    """The switched links' part of A [1/s] with the modes ``mode`` (default: every link on
    whose extra conductance is positive, the stiffest case: the spectral bound's)."""
    if len(swi) == 0:
        return sp.csr_matrix((n, n))
    w = (swg[:, 0] > 0).astype(float) if mode is None else np.asarray(mode, float)[swi[:, 2]]
    a, b = swi[:, 0], swi[:, 1]
    ga, gb = swg[:, 0] * w, swg[:, 1] * w
    rows = np.concatenate([a, a, b, b])
    cols = np.concatenate([a, b, b, a])
    vals = np.concatenate([-ga, ga, -gb, gb])
    return sp.csr_matrix((vals, (rows, cols)), shape=(n, n))


def spectral_bound(A, rooms: np.ndarray, bxu: np.ndarray, u: np.ndarray,
                   ret: np.ndarray | None = None, retc: np.ndarray | None = None) -> float:
    """L [1/s] with every eigenvalue of A(u_k) in [-L, 0] for all rows of ``u``
    (Gershgorin: A(u) is diagonally dominant with a non-positive diagonal). ``ret``,
    ``retc``: the boxes' return plenums (:attr:`~.rc.network.RCStructure.returns`), whose
    outflow adds to the plenum's diagonal."""
    A = sp.csr_matrix(A)
    diag = -A.diagonal()
    off = np.asarray(abs(A).sum(axis=1)).ravel() - np.abs(A.diagonal())
    extra = np.zeros((len(u), A.shape[0]))
    np.add.at(extra.T, rooms, (-np.asarray(bxu)[:, None]) * np.asarray(u).T)
    if ret is not None and np.any(np.asarray(ret) >= 0):
        has = np.asarray(ret) >= 0
        # the plenum's row: its outflow on the diagonal and the rooms' inflow off it
        np.add.at(extra.T, np.asarray(ret)[has],
                  2.0 * np.asarray(retc)[has][:, None] * np.asarray(u).T[has])
    return float(np.max(diag + off + extra.max(axis=0))) if len(u) else float(np.max(diag + off))


def tight_bound(A, rooms: np.ndarray, bxu: np.ndarray, u: np.ndarray, capacity: np.ndarray,
                margin: float = 1.05, ret: np.ndarray | None = None,
                retc: np.ndarray | None = None) -> float:
    """L [1/s] from the extreme eigenvalue of the symmetric form at the largest airflows.

    ``A(u) = diag(1/cap) K(u)`` is similar to ``S(u) = D^-1/2 K(u) D^-1/2`` (D = diag(cap)),
    symmetric; raising any airflow adds a negative semidefinite diagonal, so by Weyl's
    inequality the most negative eigenvalue over all rows of ``u`` is bounded by the one at
    the element-wise maximum airflow. ``margin`` covers the eigensolver's tolerance.
    ``ret``, ``retc``: as :func:`spectral_bound`. With return air A(u) is not symmetric:
    the symmetric part's extreme eigenvalue then bounds the real parts of its eigenvalues
    (numerical range), and the series keeps terms for any that leave the real axis
    (:func:`return_rho`).
    """
    A = sp.csr_matrix(A, dtype=float)
    umax = np.max(u, axis=0) if len(u) else np.zeros(len(bxu))
    dd = np.zeros(A.shape[0])
    np.add.at(dd, rooms, np.asarray(bxu) * umax)
    Au = A + sp.diags(dd)
    if ret is not None and np.any(np.asarray(ret) >= 0):
        has = np.asarray(ret) >= 0
        p, r_, g = np.asarray(ret)[has], np.asarray(rooms)[has], np.asarray(retc)[has] * umax[has]
        n = A.shape[0]
        Au = Au + sp.csr_matrix((np.concatenate([g, -g]),
                                 (np.concatenate([p, p]), np.concatenate([r_, p]))), shape=(n, n))
    sq = np.sqrt(np.asarray(capacity, float))
    S = sp.diags(sq) @ Au @ sp.diags(1.0 / sq)
    S = 0.5 * (S + S.T)
    try:
        # a fixed start vector: ARPACK's default is random, which would make the number of
        # series terms, and so the last bits of every result, differ from call to call
        lam = eigsh(S, k=1, which="SA", return_eigenvectors=False, tol=1e-6, maxiter=5000,
                    v0=np.ones(S.shape[0]))
    except ArpackNoConvergence:
        return spectral_bound(A, rooms, bxu, u, ret, retc)
    return float(min(-lam[0] * margin, spectral_bound(A, rooms, bxu, u, ret, retc)))


def simulate_exact(A, rooms: np.ndarray, bxu: np.ndarray, x0: np.ndarray, u: np.ndarray,
                   b_fixed: np.ndarray, ts: np.ndarray, h: float, tol: float = TOL,
                   capacity: np.ndarray | None = None, ret: np.ndarray | None = None,
                   retc: np.ndarray | None = None, switched=None,
                   modes: np.ndarray | None = None) -> np.ndarray:
    """States (N + 1, n) [degC] of the model stepped exactly with inputs held per step.

    Parameters
    ----------
    A : (n, n) continuous system matrix at zero airflow [1/s] (dense or sparse)
    rooms : (n_boxes,) room-air state index of each box
    bxu : (n_boxes,) the nonzero of B_xu_j: -c_p / C_room [1/s per kg/s]
    x0 : (n,) initial state [degC]
    u : (N, n_boxes) airflows [kg/s], held over each step
    b_fixed : (N, n) the airflow-independent forcing B_v v + B_IG (c_IG + f_IG) [K/s]
    ts : (N,) supply air temperature v_Ts [degC]
    h : step [s]
    tol : truncation of the Chebyshev series (relative)
    capacity : (n,) state heat capacities [J/K]; with them the spectral interval comes
        from the symmetric form's extreme eigenvalue (fewer terms), else from Gershgorin.
    ret, retc : (n_boxes,) each box's return plenum state (-1: none) and c_p / C_plenum
        (:attr:`~.rc.network.RCStructure.returns`); default none.
    switched, modes : switched links and their modes per step ((N, n_modes), 0 or 1), as
        :class:`ExactStepper`; default none.
    """
    ret, retc = _returns(ret, retc, len(rooms))
    swi, swg = _switches(switched)
    As = sp.csr_matrix(A)
    As.sum_duplicates()
    u = np.ascontiguousarray(u, dtype=float)
    if np.any(u < 0):
        raise ValueError("airflows u must be >= 0 kg/s")
    Ab = As + switched_matrix(As.shape[0], swi, swg)  # the stiffest modes bound the spectrum
    L = (tight_bound(Ab, rooms, bxu, u, capacity, ret=ret, retc=retc) if capacity is not None
         else spectral_bound(Ab, rooms, bxu, u, ret, retc))
    r = max(L * h / 2.0, 1e-12)
    coef = chebyshev_coefficients(r, tol, return_rho(Ab, rooms, bxu, ret, retc,
                                                      np.max(u, axis=0), L))
    if len(coef) < 2:
        coef = np.append(coef, 0.0)
    xs = np.empty((len(u) + 1, As.shape[0]))
    _run(As.indptr.astype(np.int64), As.indices.astype(np.int64), As.data.astype(np.float64),
         np.ascontiguousarray(rooms, dtype=np.int64), np.ascontiguousarray(bxu, float),
         ret, retc, swi, swg, np.ascontiguousarray(x0, float), u,
         _mode_rows(modes, len(u), swi), np.ascontiguousarray(b_fixed, float),
         np.ascontiguousarray(ts, float), float(h), float(r), coef, xs)
    return xs


def _mode_rows(modes, N: int, swi: np.ndarray) -> np.ndarray:
    """(N, n_modes) modes as the kernels take them: zeros (every link off) when None."""
    width = int(swi[:, 2].max()) + 1 if len(swi) else 0
    if modes is None:
        return np.zeros((N, width))
    modes = np.ascontiguousarray(np.reshape(modes, (N, -1)), dtype=float)
    if modes.shape[1] < width:
        raise ValueError(f"modes have {modes.shape[1]} columns, the switched links use {width}")
    return modes


class ExactStepper:
    """Single exact steps of one model with the set-up (sparse matrix, spectral bound,
    Chebyshev coefficients) done once, for sequential estimators that step and correct.

    Parameters
    ----------
    A, rooms, bxu, h, capacity, ret, retc : as :func:`simulate_exact`
    u_max : (n_boxes,) the largest airflows [kg/s] that will be stepped (bounds the spectrum)
    switched : (swi, swg), optional
        Links whose conductance changes with a known mode (the inside films' convection
        regime, :attr:`~.rc.network.RCStructure.switched`): ``swi`` (k, 3) the two states
        and the mode column of each link, ``swg`` (k, 2) its extra conductance over the
        first and the second state's capacity [1/s] when its mode is 1 (negative: weaker).
        The methods take the mode of each column per step (``mode``/``modes``; default 0,
        every link as in A). The series' bound covers every combination of modes.
    """

    def __init__(self, A, rooms, bxu, h: float, u_max: np.ndarray,
                 capacity: np.ndarray | None = None, tol: float = TOL,
                 ret: np.ndarray | None = None, retc: np.ndarray | None = None,
                 switched=None):
        self.A = sp.csr_matrix(A, dtype=float)
        self.A.sum_duplicates()
        self.rooms = np.ascontiguousarray(rooms, dtype=np.int64)
        self.bxu = np.ascontiguousarray(bxu, dtype=float)
        self.ret, self.retc = _returns(ret, retc, len(self.rooms))
        self.swi, self.swg = _switches(switched)
        self.n_modes = int(self.swi[:, 2].max()) + 1 if len(self.swi) else 0
        self.u_max = np.asarray(u_max, dtype=float)
        um = self.u_max[None, :]
        Ab = self.A + switched_matrix(self.A.shape[0], self.swi, self.swg)
        L = (tight_bound(Ab, self.rooms, self.bxu, um, capacity, ret=self.ret,
                         retc=self.retc) if capacity is not None
             else spectral_bound(Ab, self.rooms, self.bxu, um, self.ret, self.retc))
        self.h = float(h)
        self.r = max(L * h / 2.0, 1e-12)
        self.coef = chebyshev_coefficients(self.r, tol, return_rho(
            Ab, self.rooms, self.bxu, self.ret, self.retc, self.u_max, L))
        if len(self.coef) < 2:
            self.coef = np.append(self.coef, 0.0)
        self._ip = self.A.indptr.astype(np.int64)
        self._ix = self.A.indices.astype(np.int64)
        self._d = self.A.data.astype(np.float64)

    def step(self, x: np.ndarray, u: np.ndarray, b_fixed: np.ndarray, ts: float,
             mode: np.ndarray | None = None) -> np.ndarray:
        """x(k+1) [degC] from x(k) with airflows ``u`` [kg/s], forcing ``b_fixed`` [K/s],
        supply temperature ``ts`` [degC] and the switched links' ``mode`` held over the
        step."""
        u = self._check(u)
        out = np.empty_like(np.asarray(x, dtype=float))
        _step(self._ip, self._ix, self._d, self.rooms, self.bxu, self.ret, self.retc, self.swi,
              self.swg, np.ascontiguousarray(x, dtype=float), u, self._mode(mode),
              np.ascontiguousarray(b_fixed, float), float(ts), self.h, self.r, self.coef, out)
        return out

    def _mode(self, mode) -> np.ndarray:
        return _mode_rows(mode, 1, self.swi)[0]

    def _modes(self, modes, N: int) -> np.ndarray:
        return _mode_rows(modes, N, self.swi)

    def _check(self, u: np.ndarray) -> np.ndarray:
        u = np.ascontiguousarray(u, dtype=float)
        if np.any(u > self.u_max * (1 + 1e-12)):
            raise ValueError("airflow above the stepper's u_max: create it with the data's "
                             "largest airflows")
        return u

    def run(self, x0: np.ndarray, u: np.ndarray, b_fixed: np.ndarray,
            ts: np.ndarray, modes: np.ndarray | None = None) -> np.ndarray:
        """States (N + 1, n) [degC] from ``x0`` over N steps with inputs held per step
        (rows of ``u`` [kg/s], ``b_fixed`` [K/s], ``ts`` [degC], ``modes``); one compiled
        call, the same arithmetic as N calls of :meth:`step`."""
        u = self._check(np.atleast_2d(u))
        xs = np.empty((len(u) + 1, self.A.shape[0]))
        _run(self._ip, self._ix, self._d, self.rooms, self.bxu, self.ret, self.retc, self.swi,
             self.swg, np.ascontiguousarray(x0, dtype=float), u, self._modes(modes, len(u)),
             np.ascontiguousarray(b_fixed, float), np.ascontiguousarray(ts, float), self.h,
             self.r, self.coef, xs)
        return xs

    def propagator(self, u: np.ndarray, mode: np.ndarray | None = None) -> np.ndarray:
        """``Phi(u) = exp(A(u) h)`` (n, n) as a dense matrix, by the step's series applied to
        the identity (for filters that propagate a covariance): no eigendecomposition, a
        few milliseconds for ~400 states."""
        u = self._check(u)
        n = self.A.shape[0]
        out = np.empty((n, n))
        _block(self._ip, self._ix, self._d, self.rooms, self.bxu, self.ret, self.retc, self.swi,
               self.swg, u, self._mode(mode), np.eye(n), np.zeros((n, n)), np.zeros(n), 0.0,
               self.h, self.r, self.coef, out)
        return out

    def run_columns(self, X0: np.ndarray, u: np.ndarray, bcols: np.ndarray, s: np.ndarray,
                    ts: np.ndarray, modes: np.ndarray | None = None) -> np.ndarray:
        """States (N + 1, n, m) [degC] of m simulations that share the airflows: column c
        starts at ``X0[:, c]`` and is forced by ``bcols[:, c] * s[k, c]`` [K/s] at step k
        (plus the supply-air term with ``ts`` [degC]). Column c equals :meth:`run` with
        ``b_fixed = s[:, c, None] * bcols[:, c]`` bit for bit, at a fraction of m runs'
        cost (one compiled call, the columns' arithmetic vectorised)."""
        u = self._check(np.atleast_2d(u))
        X0 = np.ascontiguousarray(X0, dtype=float)
        n, m = X0.shape
        xs = np.empty((len(u) + 1, n, m))
        _run_block(self._ip, self._ix, self._d, self.rooms, self.bxu, self.ret, self.retc,
                   self.swi, self.swg, X0, u, self._modes(modes, len(u)),
                   np.ascontiguousarray(bcols, dtype=float),
                   np.ascontiguousarray(s, dtype=float), np.ascontiguousarray(ts, float),
                   self.h, self.r, self.coef, xs)
        return xs

    def columns(self, u: np.ndarray, B: np.ndarray, mode: np.ndarray | None = None) -> np.ndarray:
        """``Gamma(u) B`` (n, m): the one-step response of a zero state to each column of
        ``B`` [K/s per unit] held over the step, i.e. the discrete input matrix
        ``int_0^h exp(A(u) s) ds B`` of that forcing (paper eq:model_dt's B_IG for
        ``B = B_IG``)."""
        u = self._check(u)
        B = np.ascontiguousarray(B, dtype=float)
        out = np.empty(B.shape)
        _columns(self._ip, self._ix, self._d, self.rooms, self.bxu, self.ret, self.retc, self.swi,
                 self.swg, u, self._mode(mode), B, self.h, self.r, self.coef, out)
        return out


class StepperLadder:
    """Exact steppers for any airflow, built on demand on a ladder of airflow bounds.

    The stepper used for airflows ``u`` is the one whose bound ``u_base * 2**level`` is the
    smallest that covers ``max(u)``: a function of ``u`` alone, so an estimator restarted
    from a checkpoint, or run offline over the same telemetry, uses the same stepper (and
    gets the same bits) for the same step. Higher levels need a few more series terms.

    Parameters
    ----------
    A, rooms, bxu, h, capacity, ret, retc, switched : as :class:`ExactStepper`
    u_base : float
        Airflow bound of level 0 [kg/s per box], > 0.
    fixed : array (n_boxes,), optional
        A known bound [kg/s] of each box whose airflow never exceeds it (a scheduled
        input: an infiltration's design flow, a ground contact's constant G A / c_p); 0
        for the boxes the ladder bounds. Such a box keeps its own bound at every level and
        does not raise the level (a ground contact's "airflow" of tens of kg/s would
        otherwise lift every box's bound, and the series' length, with it).
    """

    def __init__(self, A, rooms, bxu, h: float, capacity: np.ndarray | None, u_base: float,
                 fixed: np.ndarray | None = None, ret: np.ndarray | None = None,
                 retc: np.ndarray | None = None, switched=None):
        if not u_base > 0:
            raise ValueError(f"u_base must be > 0 kg/s, got {u_base}")
        self.A = sp.csr_matrix(A, dtype=float)
        self.rooms = np.asarray(rooms)
        self.bxu = np.asarray(bxu, dtype=float)
        self.h = float(h)
        self.capacity = capacity
        self.ret, self.retc = _returns(ret, retc, len(self.rooms))
        self.switched = switched
        self.u_base = float(u_base)
        self.fixed = (np.zeros(len(self.rooms)) if fixed is None
                      else np.asarray(fixed, dtype=float))
        if self.fixed.shape != (len(self.rooms),) or (self.fixed < 0).any():
            raise ValueError("fixed must hold one bound >= 0 kg/s per box")
        self._free = self.fixed == 0
        self._levels: dict[int, ExactStepper] = {}

    def level(self, u: np.ndarray) -> int:
        """Ladder level covering every airflow in ``u`` [kg/s] (a box with a fixed bound
        counts only where its airflow exceeds that bound)."""
        u = np.asarray(u, dtype=float)
        if np.size(u) and (not np.isfinite(u).all() or np.min(u) < 0):
            raise ValueError("airflows must be finite and >= 0 kg/s")
        if np.size(u) and not self._free.all():
            over = u > self.fixed
            u = np.where(self._free | over, u, 0.0)
        top = float(np.max(u)) if np.size(u) else 0.0
        return max(0, int(np.ceil(np.log2(top / self.u_base)))) if top > self.u_base else 0

    def for_airflows(self, u: np.ndarray) -> ExactStepper:
        """The stepper for the airflows ``u`` (one row or many) [kg/s]."""
        k = self.level(u)
        st = self._levels.get(k)
        if st is None:
            top = self.u_base * 2.0**k
            bound = np.where(self._free, top, np.maximum(self.fixed, top))
            st = ExactStepper(self.A, self.rooms, self.bxu, self.h, bound, self.capacity,
                              ret=self.ret, retc=self.retc, switched=self.switched)
            self._levels[k] = st
        return st


def compile_kernels() -> int:
    """Compile the stepping kernels once, into numba's cache beside this module
    (``cache=True``), by stepping a three-state chain through every public entry point
    with the argument types the estimator uses; ``make venv`` calls it, so the test
    processes and the first service start load the kernels instead of compiling each
    (~13 s per process cold). Returns the number of kernels."""
    A = sp.csr_matrix(np.array([[-2e-3, 1e-3, 0.0], [1e-3, -2e-3, 1e-3], [0.0, 1e-3, -2e-3]]))
    st = ExactStepper(A, np.array([0]), np.array([-1e-3]), 900.0, np.array([1.0]),
                      capacity=np.ones(3))
    x, b = np.full(3, 20.0), np.zeros(3)
    st.step(x, np.array([0.5]), b, 14.0)
    st.run(x, np.full((2, 1), 0.5), np.zeros((2, 3)), np.full(2, 14.0))
    st.run_columns(np.ones((3, 2)), np.full((2, 1), 0.5), np.ones((3, 2)), np.ones((2, 2)),
                   np.full(2, 14.0))
    st.propagator(np.array([0.5]))
    st.columns(np.array([0.5]), np.ones((3, 2)))
    return len(_KERNELS)


_KERNELS = ("_return_terms", "_step", "_block", "_run_block", "_columns", "_run")
