"""State estimation for the discretised building model with a Kalman filter.

For a fixed input sequence the bilinear model (paper eq:model_dt) is a linear
time-varying system

    x(k+1) = F_k x(k) + c_k + w(k),      w(k) ~ N(0, Q)
    y(k)   = H x(k) + e(k),              e(k) ~ N(0, R)

with ``F_k = A + sum_j B_xu_j u_j(k)`` and
``c_k = B_v v(k) + B_IG (c_IG + f_IG(k)) + sum_j B_vu_j v(k) u_j(k)``. The model
class builds ``F_k`` and ``c_k``; this module only filters. The filter is
filterpy's :class:`filterpy.kalman.KalmanFilter` (state, covariance, predict); the
update is the Joseph form ``P = (I - K H) P (I - K H)' + K R K'`` that filterpy's
update computes, evaluated here with ``I - K H`` as identity minus a rank-m product
(O(n² m) rather than O(n³); docs/numerics.md). The covariance is additionally
symmetrised after every predict and update.

Missing measurements (NaN entries of ``y``) drop the corresponding rows of
``H``, ``y`` and rows/columns of ``R`` for that update; an all-NaN ``y`` means
no update (predict only).

The paper needs the filter for x(0) of the parameter identification (section
"Parameter Identification", x(0) = x_KF(0)) and every 24 h before a forecast.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
from filterpy.kalman import KalmanFilter
from scipy.linalg import solve_discrete_are

__all__ = [
    "FilterResult",
    "HorizonRows",
    "Innovation",
    "KalmanInputError",
    "SteadyStateFilter",
    "YoungFilter",
    "ZoneStateFilter",
    "air_wall_covariance",
    "default_initial_covariance",
    "default_measurement_noise",
    "default_process_noise",
    "horizon_output_variances",
    "initial_state_from_measurement",
    "run_filter",
    "steady_state_covariance",
    "young_filter",
]

StepFn = Callable[[int], tuple[np.ndarray, np.ndarray | None]]


class KalmanInputError(ValueError):
    """Inconsistent shapes or invalid values given to the filter."""


def _square(name: str, M, n: int) -> np.ndarray:
    """Accept a (n, n) matrix or a (n,) vector of variances (-> diagonal)."""
    A = np.asarray(M, dtype=float)
    if A.ndim == 1:
        if A.shape != (n,):
            raise KalmanInputError(f"{name} as variances must have shape ({n},), got {A.shape}")
        if np.any(A < 0) or not np.all(np.isfinite(A)):
            raise KalmanInputError(f"{name} variances must be finite and >= 0")
        return np.diag(A)
    if A.shape != (n, n):
        raise KalmanInputError(
            f"{name} must have shape ({n}, {n}) or be a ({n},) vector of variances, got {A.shape}"
        )
    if not np.all(np.isfinite(A)):
        raise KalmanInputError(f"{name} must be finite")
    if not np.allclose(A, A.T, rtol=1e-10, atol=1e-12 * max(1.0, np.abs(A).max())):
        raise KalmanInputError(f"{name} must be symmetric")
    return 0.5 * (A + A.T)


@dataclass(frozen=True)
class Innovation:
    """Statistics of one measurement update.

    Attributes
    ----------
    innovation : numpy.ndarray, shape (m_obs,)
        ``y_obs - H_obs x_prior`` [K] for the observed outputs only.
    S : numpy.ndarray, shape (m_obs, m_obs)
        Innovation covariance ``H_obs P_prior H_obs' + R_obs`` [K²].
    nis : float
        Normalised innovation squared ``innovation' S^-1 innovation`` [-];
        chi²(m_obs)-distributed for a consistent filter; NaN if no update.
    observed : numpy.ndarray, shape (m,), bool
        Which outputs took part in the update.
    """

    innovation: np.ndarray
    S: np.ndarray
    nis: float
    observed: np.ndarray

    @property
    def dof(self) -> int:
        """Number of observed outputs (degrees of freedom of the NIS)."""
        return int(self.observed.sum())


_ONE = np.ones(1)


class ZoneStateFilter:
    """Kalman filter for x(k+1) = F_k x(k) + c_k + w, y(k) = H x(k) + e.

    Parameters
    ----------
    x0 : array_like, shape (n,)
        Prior mean of the state at the first time [°C].
    P0 : array_like, shape (n, n) or (n,)
        Prior covariance [K²] (a vector is read as variances).
    H : array_like, shape (m, n)
        Output matrix (the model's C) [-].
    Q : array_like, shape (n, n) or (n,)
        Process-noise covariance per step [K²]; see :func:`default_process_noise`.
    R : array_like, shape (m, m) or (m,)
        Measurement-noise covariance [K²]; see :func:`default_measurement_noise`.
    """

    def __init__(self, x0, P0, H, Q, R):
        x0 = np.asarray(x0, dtype=float)
        if x0.ndim != 1 or not np.all(np.isfinite(x0)):
            raise KalmanInputError(
                "x0 must be a finite 1-D state vector; see initial_state_from_measurement()"
            )
        n = x0.shape[0]
        H = np.asarray(H, dtype=float)
        if H.ndim != 2 or H.shape[1] != n:
            raise KalmanInputError(f"H must have shape (m, {n}) to match x0, got {H.shape}")
        m = H.shape[0]
        self._n, self._m = n, m
        self._H = H
        self._R = _square("R", R, m)
        self._Q = _square("Q", Q, n)
        kf = KalmanFilter(dim_x=n, dim_z=m)
        kf.x = x0.copy()
        kf.P = _square("P0", P0, n)
        kf.H = H
        kf.R = self._R
        kf.Q = self._Q
        self._kf = kf

    @property
    def dim_x(self) -> int:
        """Number of states n."""
        return self._n

    @property
    def dim_y(self) -> int:
        """Number of outputs m."""
        return self._m

    @property
    def x(self) -> np.ndarray:
        """Current state estimate [°C], shape (n,) (a copy)."""
        return np.array(self._kf.x, dtype=float)

    @property
    def P(self) -> np.ndarray:
        """Current state covariance [K²], shape (n, n) (a copy)."""
        return np.array(self._kf.P, dtype=float)

    def predict(self, F, c=None, Q=None) -> None:
        """Time update x <- F x + c, P <- F P F' + Q.

        Parameters
        ----------
        F : array_like, shape (n, n)
            State-transition matrix of this step [-].
        c : array_like, shape (n,), optional
            Affine input term of this step [°C]; zero if omitted.
        Q : array_like, shape (n, n) or (n,), optional
            Process noise for this step only [K²]; the filter's Q if omitted.
        """
        n = self._n
        F = np.asarray(F, dtype=float)
        if F.shape != (n, n):
            raise KalmanInputError(f"F must have shape ({n}, {n}), got {F.shape}")
        Qk = self._Q if Q is None else _square("Q", Q, n)
        if c is None:
            self._kf.predict(F=F, Q=Qk)
        else:
            c = np.asarray(c, dtype=float)
            if c.shape != (n,):
                raise KalmanInputError(f"c must have shape ({n},), got {c.shape}")
            # filterpy adds B u; with B = c as one column and u = 1 that is exactly c
            self._kf.predict(u=_ONE, B=c[:, None], F=F, Q=Qk)
        P = self._kf.P
        self._kf.P = 0.5 * (P + P.T)

    def update(self, y) -> Innovation:
        """Measurement update with the observed (non-NaN) entries of ``y``.

        Parameters
        ----------
        y : array_like, shape (m,)
            Measured outputs [°C]; NaN marks a missing measurement.

        Returns
        -------
        Innovation
            Innovation, its covariance and NIS for the observed rows; with no
            observed row the state is unchanged and ``nis`` is NaN.
        """
        y = np.asarray(y, dtype=float)
        if y.shape != (self._m,):
            raise KalmanInputError(f"y must have shape ({self._m},), got {y.shape}")
        obs = ~np.isnan(y)
        if not obs.any():
            return Innovation(np.empty(0), np.empty((0, 0)), float("nan"), obs)
        H = self._H[obs]
        R = self._R[np.ix_(obs, obs)]
        kf = self._kf
        P = kf.P
        PHt = P @ H.T                                   # (n, m)
        S = H @ PHt + R
        K = np.linalg.solve(S.T, PHt.T).T               # P H' S^-1
        nu = y[obs] - H @ kf.x
        # Joseph form (I - K H) P (I - K H)' + K R K' as filterpy's update computes it, but
        # with I - K H applied as identity minus a rank-m product: O(n² m) instead of the
        # O(n³) of forming I - K H (8.3 -> 1.6 ms of CPU per update at n = 381; docs/numerics.md)
        M = P - K @ (H @ P)                             # (I - K H) P
        P = M - (M @ H.T) @ K.T + K @ R @ K.T
        kf.x = kf.x + K @ nu
        kf.P = 0.5 * (P + P.T)
        kf.y, kf.S, kf.K = nu, S, K
        nis = float(nu @ np.linalg.solve(S, nu))
        return Innovation(np.array(nu, dtype=float), np.array(S, dtype=float), nis, obs)


def steady_state_covariance(F, H, Q, R) -> np.ndarray:
    """Prior (predicted) covariance of the time-invariant Kalman filter [K²].

    The fixed point of ``P = F (P - P H' (H P H' + R)^-1 H P) F' + Q``, the discrete
    algebraic Riccati equation, solved by :func:`scipy.linalg.solve_discrete_are` (the
    filter form is the control form with F' and H'). The filter with constant F, Q, R
    converges to it from any positive semidefinite start when (F, H) is detectable.

    Parameters
    ----------
    F : (n, n) state transition [-]; H : (m, n) output matrix [-];
    Q : (n, n) or (n,) process noise [K²]; R : (m, m) or (m,) measurement noise [K²].
    """
    F = np.asarray(F, dtype=float)
    n = F.shape[0]
    if F.shape != (n, n):
        raise KalmanInputError(f"F must be square, got {F.shape}")
    H = np.asarray(H, dtype=float)
    if H.ndim != 2 or H.shape[1] != n:
        raise KalmanInputError(f"H must have shape (m, {n}), got {H.shape}")
    Q = _square("Q", Q, n)
    R = _square("R", R, H.shape[0])
    try:
        P = solve_discrete_are(F.T, H.T, Q, R)
    except (ValueError, np.linalg.LinAlgError) as exc:
        raise KalmanInputError(f"no steady-state filter for this model ({exc}); check that "
                               "every zone is measured and the model is stable") from exc
    return 0.5 * (P + P.T)


def horizon_output_variances(F, P0, Q, H, steps: int) -> np.ndarray:
    """Variances of ``H x`` after 1..``steps`` predictions ``x <- F x + w`` [K²].

    ``P_h = F^h P0 F^h' + sum_{j<h} F^j Q F^j'`` is never formed: only the rows
    ``G_h = H F^h`` are propagated (m x n each), so the cost is O(steps m n²) instead of
    O(steps n³) (:class:`HorizonRows`, which serves several ``P0`` of the same system).

    Returns
    -------
    ndarray (steps, m)
    """
    F = np.asarray(F, dtype=float)
    return HorizonRows(F, _square("Q", Q, F.shape[0]), H, steps).variances(P0)


class HorizonRows:
    """The rows ``G_h = H F^h`` (h = 1..steps) of a system and the process noise's part of
    the forecast output variances, ``sum_{j<h} diag(G_j Q G_j')`` (G_0 = H): what
    :func:`horizon_output_variances` needs besides the initial covariance, computed once.

    Parameters
    ----------
    F : (n, n) [-]; Q : (n, n) [K²]; H : (m, n) [-]; steps : int
    """

    def __init__(self, F, Q, H, steps: int):
        F = np.asarray(F, dtype=float)
        G = np.asarray(H, dtype=float)
        m, n = G.shape
        rows = np.empty((steps + 1, m, n))
        rows[0] = G
        for h in range(steps):
            rows[h + 1] = rows[h] @ F
        flat = rows.reshape(-1, n)
        q = ((flat @ np.asarray(Q, float)) * flat).sum(axis=1).reshape(steps + 1, m)
        self.n = n
        self.rows = rows[1:]
        self.noise = np.cumsum(q[:-1], axis=0)

    def variances(self, P0) -> np.ndarray:
        """(steps, m) forecast output variances [K²] from the covariance ``P0``."""
        P0 = _square("P0", P0, self.n)
        flat = self.rows.reshape(-1, self.n)
        return ((flat @ P0) * flat).sum(axis=1).reshape(self.rows.shape[:2]) + self.noise


class SteadyStateFilter:
    """Measurement update of the time-invariant (steady-state) Kalman filter.

    The prediction is the model's (any exact stepper); the update uses the fixed prior
    covariance ``P`` of :func:`steady_state_covariance`. With the observed rows ``S`` of
    ``y`` the gain is ``K_S = P H_S' (H_S P H_S' + R_SS)^-1``; gains are cached per
    pattern of observed rows, so a partial measurement costs one small solve the first
    time it occurs. The update is O(n m) instead of the O(n³) of the time-varying filter
    (:class:`ZoneStateFilter`); the price is that P does not follow the airflows or grow
    during outages (docs/service.md says how the service reports that).

    Parameters
    ----------
    P : (n, n) prior covariance [K²]; H : (m, n) [-]; R : (m, m) or (m,) [K²].
    """

    def __init__(self, P, H, R):
        H = np.asarray(H, dtype=float)
        n = H.shape[1]
        self.P = _square("P", P, n)
        self.H = H
        self.R = _square("R", R, H.shape[0])
        self._PHt = self.P @ H.T                 # (n, m)
        self._HPHt = H @ self._PHt              # (m, m)
        self._cache: dict[bytes, tuple[np.ndarray, ...]] = {}

    def _pattern(self, obs: np.ndarray):
        key = obs.tobytes()
        hit = self._cache.get(key)
        if hit is None:
            S = self._HPHt[np.ix_(obs, obs)] + self.R[np.ix_(obs, obs)]
            S = 0.5 * (S + S.T)
            Sinv = np.linalg.inv(S)
            K = self._PHt[:, obs] @ Sinv
            # posterior output covariance H P+ H' = HPH' - HPH'[:, S] S^-1 HPH'[S, :]
            post = self._HPHt - self._HPHt[:, obs] @ Sinv @ self._HPHt[obs, :]
            hit = (K, S, Sinv, 0.5 * (post + post.T))
            self._cache[key] = hit
        return hit

    def update(self, x_prior, y) -> tuple[np.ndarray, Innovation]:
        """Posterior state [°C] and innovation statistics for measurement ``y`` (NaN =
        missing; all missing: the prior is returned and ``nis`` is NaN)."""
        y = np.asarray(y, dtype=float)
        if y.shape != (self.H.shape[0],):
            raise KalmanInputError(f"y must have shape ({self.H.shape[0]},), got {y.shape}")
        obs = ~np.isnan(y)
        x_prior = np.asarray(x_prior, dtype=float)
        if not obs.any():
            return x_prior.copy(), Innovation(np.empty(0), np.empty((0, 0)), float("nan"), obs)
        K, S, Sinv, _ = self._pattern(obs)
        nu = y[obs] - self.H[obs] @ x_prior
        return x_prior + K @ nu, Innovation(nu, S, float(nu @ Sinv @ nu), obs)

    def output_covariance(self, obs=None) -> np.ndarray:
        """Posterior covariance of ``H x`` [K²] after an update with the rows ``obs``
        observed (default all)."""
        obs = np.ones(self.H.shape[0], bool) if obs is None else np.asarray(obs, bool)
        if not obs.any():
            return self._HPHt.copy()
        return self._pattern(obs)[3].copy()

    def posterior(self) -> np.ndarray:
        """Posterior state covariance after a complete measurement [K²]."""
        K = self._pattern(np.ones(self.H.shape[0], bool))[0]
        P = self.P - K @ self._PHt.T
        return 0.5 * (P + P.T)


@dataclass(frozen=True)
class YoungFilter:
    """Gains of the time-invariant Kalman filter in its first steps after a start.

    Step j (1..``steps``) of the filter started from ``P0`` and updated with every output
    at the start and at each step: ``P_j- = F P_(j-1)+ F' + Q``,
    ``K_j = P_j- H' S_j^-1`` with ``S_j = H P_j- H' + R``, ``P_j+ = (I - K_j H) P_j-``.
    They depend on j only, not on the data, so they are computed once per model; the
    steady-state filter (:class:`SteadyStateFilter`) is their limit.

    Attributes
    ----------
    gains : ndarray (steps, n, m)
        ``K_j`` at index j - 1 [-].
    S : ndarray (steps, m, m)
        Innovation covariances ``S_j`` [K²]; ``S_inv`` their inverses [1/K²].
    output_var : ndarray (steps + 1, m)
        ``diag(H P_j+ H')`` for j = 0..steps [K²].
    horizon_at : ndarray of int
        Steps j at which ``horizon_var`` was evaluated (0, 1, 2, 4, ...).
    horizon_var : ndarray (len(horizon_at), horizon, m)
        :func:`horizon_output_variances` from ``P_j+`` [K²].
    """

    gains: np.ndarray
    S: np.ndarray
    S_inv: np.ndarray
    output_var: np.ndarray
    horizon_at: np.ndarray
    horizon_var: np.ndarray

    @property
    def steps(self) -> int:
        return len(self.gains)

    def horizon_variance(self, j: int) -> np.ndarray:
        """Forecast output variances (horizon, m) [K²] after step j: those of the latest
        evaluated step at or before j (never narrower than the filter's at j, since
        ``P_j+`` shrinks with j)."""
        i = int(np.searchsorted(self.horizon_at, j, side="right")) - 1
        return self.horizon_var[max(i, 0)]


def young_filter(F, H, Q, R, P0, steps: int, horizon: int, *,
                 rtol: float = 1e-3, steady: SteadyStateFilter | None = None,
                 rows: HorizonRows | None = None) -> YoungFilter:
    """The time-varying gains of the filter from ``P0`` for up to ``steps`` steps
    (:class:`YoungFilter`), ending early once the gain is within ``rtol`` (relative to
    its largest entry) of the steady-state gain.

    Parameters
    ----------
    F : (n, n) [-]; H : (m, n) [-]; Q : (n, n) or (n,) [K²]; R : (m, m) or (m,) [K²];
    P0 : (n, n) or (n,) covariance at the start, before its measurement [K²];
    steps : int, steps to compute at most; horizon : int, forecast steps.
    steady : the steady-state filter of the same F, H, Q, R, if at hand (its gain ends the
        recursion; without it the Riccati equation is solved again).
    rows : the :class:`HorizonRows` of the same F, Q, H and ``horizon``, if at hand.
    """
    F = np.asarray(F, dtype=float)
    n = F.shape[0]
    H = np.asarray(H, dtype=float)
    Q, R, P = _square("Q", Q, n), _square("R", R, H.shape[0]), _square("P0", P0, n)
    if steady is None:
        steady = SteadyStateFilter(steady_state_covariance(F, H, Q, R), H, R)
    K_ss = steady._pattern(np.ones(H.shape[0], bool))[0]
    scale = max(float(np.abs(K_ss).max()), 1e-12)

    def update(P):
        S = H @ P @ H.T + R
        S = 0.5 * (S + S.T)
        S_inv = np.linalg.inv(S)
        K = P @ H.T @ S_inv
        P = P - K @ (H @ P)
        return 0.5 * (P + P.T), K, S, S_inv

    P = update(P)[0]
    rows = HorizonRows(F, Q, H, horizon) if rows is None else rows
    gains, Ss, Sis, out_var, at, hv = [], [], [], [np.diag(H @ P @ H.T)], [0], []
    hv.append(rows.variances(P))
    for j in range(1, steps + 1):
        P, K, S, S_inv = update(F @ P @ F.T + Q)
        gains.append(K)
        Ss.append(S)
        Sis.append(S_inv)
        out_var.append(np.diag(H @ P @ H.T))
        if j & (j - 1) == 0:  # powers of two
            at.append(j)
            hv.append(rows.variances(P))
        if np.abs(K - K_ss).max() <= rtol * scale:
            break
    m = H.shape[0]
    return YoungFilter(np.array(gains).reshape(-1, n, m), np.array(Ss).reshape(-1, m, m),
                       np.array(Sis).reshape(-1, m, m), np.array(out_var),
                       np.array(at, dtype=int), np.array(hv))


@dataclass(frozen=True)
class FilterResult:
    """Output of :func:`run_filter`.

    Attributes
    ----------
    x : numpy.ndarray, shape (N, n)
        Filtered states ``E[x(k) | y(0..k)]`` [°C].
    P : numpy.ndarray or None
        Covariances [K²]: shape (N, n) diagonals, (N, n, n) full, or None.
    innovation : numpy.ndarray, shape (N, m)
        ``y(k) - H x(k|k-1)`` [K]; NaN where the output was not observed.
    nis : numpy.ndarray, shape (N,)
        Normalised innovation squared [-]; NaN where no update happened.
    dof : numpy.ndarray, shape (N,), int
        Number of observed outputs per step.
    """

    x: np.ndarray
    P: np.ndarray | None
    innovation: np.ndarray
    nis: np.ndarray
    dof: np.ndarray


def _step_source(steps, n_steps: int, n: int) -> StepFn:
    if callable(steps):
        return steps
    if not (isinstance(steps, Sequence) and len(steps) == 2):
        raise KalmanInputError(
            "steps must be a callable step(k) -> (F_k, c_k) or a pair (F, c) with F of shape "
            "(n, n) or (N-1, n, n) and c None, (n,) or (N-1, n)"
        )
    F, c = steps
    F = np.asarray(F, dtype=float)
    if F.shape != (n, n) and F.shape != (n_steps, n, n):
        raise KalmanInputError(f"F must have shape ({n}, {n}) or ({n_steps}, {n}, {n}), got {F.shape}")
    if c is not None:
        c = np.asarray(c, dtype=float)
        if c.shape != (n,) and c.shape != (n_steps, n):
            raise KalmanInputError(f"c must have shape ({n},) or ({n_steps}, {n}), got {c.shape}")

    def step(k: int):
        Fk = F if F.ndim == 2 else F[k]
        ck = None if c is None else (c if c.ndim == 1 else c[k])
        return Fk, ck

    return step


def run_filter(
    x0,
    P0,
    steps,
    Y,
    H,
    Q,
    R,
    *,
    store_covariance: Literal["diag", "full", "none"] = "diag",
) -> FilterResult:
    """Filter a whole series.

    Time convention: ``(x0, P0)`` is the prior at time 0; step 0 updates it with
    ``Y[0]``; for k >= 1 the filter predicts with ``steps`` for the transition
    k-1 -> k and updates with ``Y[k]``.

    Parameters
    ----------
    x0 : array_like, shape (n,)
        Prior mean at time 0 [°C].
    P0 : array_like, shape (n, n) or (n,)
        Prior covariance at time 0 [K²].
    steps : callable or (F, c)
        ``steps(k) -> (F_k, c_k)`` for k = 0..N-2 (c_k may be None), or a pair
        of arrays: F with shape (n, n) (constant) or (N-1, n, n), c None,
        (n,) or (N-1, n) [°C].
    Y : array_like, shape (N, m)
        Measurements [°C]; NaN entries are missing.
    H : array_like, shape (m, n)
        Output matrix [-].
    Q : array_like, shape (n, n) or (n,)
        Process-noise covariance per step [K²].
    R : array_like, shape (m, m) or (m,)
        Measurement-noise covariance [K²].
    store_covariance : {"diag", "full", "none"}, default "diag"
        What to keep of P for each step.

    Returns
    -------
    FilterResult
    """
    Y = np.asarray(Y, dtype=float)
    kf = ZoneStateFilter(x0, P0, H, Q, R)
    n, m = kf.dim_x, kf.dim_y
    if Y.ndim != 2 or Y.shape[1] != m:
        raise KalmanInputError(f"Y must have shape (N, {m}) to match H, got {Y.shape}")
    if store_covariance not in ("diag", "full", "none"):
        raise KalmanInputError(
            f"store_covariance must be 'diag', 'full' or 'none', got {store_covariance!r}"
        )
    N = Y.shape[0]
    step = _step_source(steps, max(N - 1, 0), n)
    xs = np.empty((N, n))
    Ps = {"diag": np.empty((N, n)), "full": np.empty((N, n, n)), "none": None}[store_covariance]
    innov = np.full((N, m), np.nan)
    nis = np.full(N, np.nan)
    dof = np.zeros(N, dtype=int)
    for k in range(N):
        if k > 0:
            Fk, ck = step(k - 1)
            kf.predict(Fk, ck)
        inn = kf.update(Y[k])
        innov[k, inn.observed] = inn.innovation
        nis[k] = inn.nis
        dof[k] = inn.dof
        xs[k] = kf._kf.x
        if store_covariance == "diag":
            Ps[k] = np.diag(kf._kf.P)
        elif store_covariance == "full":
            Ps[k] = kf._kf.P
    return FilterResult(xs, Ps, innov, nis, dof)


def initial_state_from_measurement(y0, state_zone) -> np.ndarray:
    """Initial state with every state of a zone at that zone's measured temperature.

    Walls are not measured, so the usual start is to put all building elements
    of a zone (air, walls, floor, ceiling) at the zone's measured temperature
    and give the unmeasured states a large initial variance
    (:func:`default_initial_covariance`); the filter then converges.

    Parameters
    ----------
    y0 : array_like, shape (m,)
        First measured zone temperatures [°C]; NaN for a zone not measured.
    state_zone : array_like of int, shape (n,)
        Zone index (0..m-1) of every state, or -1 for states belonging to no
        single zone (e.g. a wall between two zones).

    Returns
    -------
    numpy.ndarray, shape (n,)
        States of a measured zone get its temperature; states of an unmeasured
        zone and states with index -1 get the mean of the measured zones [°C].
    """
    y0 = np.asarray(y0, dtype=float)
    zones = np.asarray(state_zone)
    if y0.ndim != 1:
        raise KalmanInputError(f"y0 must be 1-D (one temperature per zone), got shape {y0.shape}")
    if zones.ndim != 1 or not np.issubdtype(zones.dtype, np.integer):
        raise KalmanInputError("state_zone must be a 1-D integer array (zone index or -1 per state)")
    m = y0.shape[0]
    if np.any((zones < -1) | (zones >= m)):
        raise KalmanInputError(f"state_zone entries must be in -1..{m - 1} for {m} zones")
    measured = ~np.isnan(y0)
    if not measured.any():
        raise KalmanInputError(
            "y0 has no measured zone; start the filter at the first time with a measurement"
        )
    fill = y0[measured].mean()
    per_zone = np.where(measured, y0, fill)
    return np.where(zones >= 0, per_zone[np.clip(zones, 0, None)], fill)


def _air_mask(n: int, air_states) -> np.ndarray:
    mask = np.zeros(n, dtype=bool)
    idx = np.asarray(air_states)
    if idx.dtype == bool:
        if idx.shape != (n,):
            raise KalmanInputError(f"air_states as a mask must have shape ({n},), got {idx.shape}")
        return idx.copy()
    if idx.size and (idx.min() < 0 or idx.max() >= n):
        raise KalmanInputError(f"air_states indices must be in 0..{n - 1}")
    mask[idx.astype(int)] = True
    return mask


def air_wall_covariance(n: int, air_states, sigma_air: float, sigma_wall: float) -> np.ndarray:
    """Diagonal covariance with one standard deviation for room air, another for walls.

    Parameters
    ----------
    n : int
        Number of states.
    air_states : array_like of int or bool mask
        States that are room air (the rows touched by B_IG and the HVAC term);
        all other states are walls, floors and ceilings.
    sigma_air, sigma_wall : float
        Standard deviations for air and wall states [K]; >= 0.

    Returns
    -------
    numpy.ndarray, shape (n, n)
        ``diag(sigma_air² or sigma_wall²)`` [K²].
    """
    if sigma_air < 0 or sigma_wall < 0:
        raise KalmanInputError("sigma_air and sigma_wall must be >= 0")
    return np.diag(np.where(_air_mask(n, air_states), sigma_air**2, sigma_wall**2))


def default_process_noise(
    n: int, air_states, *, sigma_air: float = 0.1, sigma_wall: float = 0.01
) -> np.ndarray:
    """Diagonal process-noise covariance Q per 15-min step [K²].

    :func:`air_wall_covariance` with defaults: ``sigma_air`` = 0.1 K, the
    unmodelled change of a room-air temperature per step (internal-gain, reheat
    and airflow errors); ``sigma_wall`` = 0.01 K, heavy elements move slowly.
    """
    return air_wall_covariance(n, air_states, sigma_air, sigma_wall)


def default_measurement_noise(m: int, *, sigma: float = 0.2) -> np.ndarray:
    """Diagonal measurement-noise covariance R.

    Parameters
    ----------
    m : int
        Number of measured zone temperatures.
    sigma : float, default 0.2
        Standard deviation of a zone-average temperature measurement [K]
        (sensor accuracy plus the gap between a few sensors and the zone mean).

    Returns
    -------
    numpy.ndarray, shape (m, m)
        ``sigma² I`` [K²].
    """
    if sigma <= 0:
        raise KalmanInputError("sigma must be > 0 (R must be positive definite)")
    return np.eye(m) * sigma**2


def default_initial_covariance(
    n: int, air_states, *, sigma_air: float = 0.3, sigma_wall: float = 2.0
) -> np.ndarray:
    """Diagonal initial covariance P0 [K²] to pair with :func:`initial_state_from_measurement`.

    :func:`air_wall_covariance` with defaults: ``sigma_air`` = 0.3 K for room air
    started at its measured temperature; ``sigma_wall`` = 2 K for unmeasured walls,
    which can sit a few kelvin from the air (exterior walls in winter, slabs).
    """
    if sigma_air <= 0 or sigma_wall <= 0:
        raise KalmanInputError("sigma_air and sigma_wall must be > 0 (P0 must be positive definite)")
    return air_wall_covariance(n, air_states, sigma_air, sigma_wall)
