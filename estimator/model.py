"""The bilinear building model: continuous matrices, 15-min discretisation, simulation.

Paper eq:ct_model (continuous) and eq:model_dt (discrete)::

    x(k+1) = A x + B_v v + B_IG (c_IG + f_IG) + sum_j (B_xu_j x + B_vu_j v) u_j
    y(k)   = C x

Three ways to step it are offered (see ``docs/model.md`` for the measured errors):

``"exact"`` (default)
    Zero-order hold with the step's u: u and v are held over the step and the
    full bilinear system, which is linear for a fixed u, is integrated exactly.
    The step's matrix exponential is applied to the state by a Chebyshev series
    in the sparse generator (:mod:`zonecast.estimator.integrate`), equal to the
    dense exponential to round-off, at a cost independent of how many distinct
    airflows occur. Unconditionally stable for any airflow.
``"eig"``
    The same zero-order-hold solution from dense propagators exp(A(u) h)
    computed by symmetric eigendecomposition and cached per distinct u; an
    independent reference, slow when airflows vary (one decomposition per
    distinct u).
``"bilinear"``
    The paper's fixed-matrix form: the exact step map linearised in u around a
    nominal airflow (Fréchet derivative of the matrix exponential). Accurate
    near the nominal flow only: room air relaxes in ~5 min at full airflow, much
    faster than the 15-min step, so the map is strongly nonlinear in u.
"""

from __future__ import annotations

import json
import warnings
from collections import OrderedDict
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import scipy.linalg as sla
from zonecast.estimator.constants import STEP_S
from zonecast.estimator.idf import Building
from zonecast.estimator.integrate import simulate_exact
from zonecast.estimator.rc.network import (
    DISTURBANCES,
    REGIME_RISE,
    ModelOptions,
    RCStructure,
    build_structure,
)
from zonecast.estimator.rc.parameters import ParameterSet

__all__ = ["BilinearModel", "DiscreteBilinear", "SimulationResult", "write_model_summary"]

#: Model step of the paper [s] (eq:model_dt); :data:`zonecast.estimator.constants.STEP_S`.
STEP = STEP_S
#: ways to step the model, see the module docstring
METHODS = ("exact", "eig", "bilinear")


@dataclass(frozen=True)
class SimulationResult:
    """States and outputs of a simulation.

    Attributes
    ----------
    x : ndarray, shape (N + 1, n)
        States [degC]; ``x[0]`` is the initial state.
    y : ndarray, shape (N + 1, n_zones)
        Zone temperatures C x [degC].
    """

    x: np.ndarray
    y: np.ndarray


@dataclass(frozen=True)
class DiscreteBilinear:
    """Fixed matrices of paper eq:model_dt.

    Attributes
    ----------
    A : ndarray (n, n)
    Bv : ndarray (n, 7)
    B_ig : ndarray (n, n_zones)
    Bxu : ndarray (n_boxes, n, n)
    Bvu : ndarray (n_boxes, n, 7)
    C : ndarray (n_zones, n)
    u_nominal : ndarray (n_boxes,)
        Airflow around which the step map was linearised [kg/s].
    """

    A: np.ndarray
    Bv: np.ndarray
    B_ig: np.ndarray
    Bxu: np.ndarray
    Bvu: np.ndarray
    C: np.ndarray
    u_nominal: np.ndarray


class BilinearModel:
    """Bilinear RC model of a building with its parameters.

    Parameters
    ----------
    structure : RCStructure
        From :func:`zonecast.estimator.rc.network.build_structure` (parameter free).
    params : ParameterSet, optional
        Defaults to the physical starting values.
    step : float
        Discretisation step [s]; the paper uses 900.
    method : {"exact", "eig", "bilinear"}
        Default discretisation for :meth:`simulate`.
    u_nominal : float or array
        Airflow per box [kg/s] for the ``"bilinear"`` linearisation.
    cache_size : int, optional
        Number of per-u step propagators kept; default fits in about 256 MB.
    reheat_scale : array, optional
        Per box, the factor on its measured reheat heat reaching the room air in
        :meth:`reheat_forcing` (default 1: the heat as measured);
        :meth:`Pipeline.fit_reheat_leak
        <zonecast.estimator.pipeline.Pipeline.fit_reheat_leak>` sets it from operation.
    reheat_from_faces : bool
        With ``reheat_scale``: the air's extra (or missing) heat is drawn from (or given to)
        the room's inside faces in proportion to their film conductances to the air, so
        the reheat's total heat stays the measured one (default False: added).
    """

    def __init__(
        self,
        structure: RCStructure,
        params: ParameterSet | None = None,
        step: float = STEP,
        method: str = "exact",
        u_nominal: float | Sequence[float] = 0.3,
        cache_size: int | None = None,
        reheat_scale: Sequence[float] | np.ndarray | None = None,
        reheat_from_faces: bool = False,
    ):
        if method not in METHODS:
            raise ValueError(f"method must be one of {METHODS}")
        if step <= 0:
            raise ValueError("step must be positive [s]")
        self.structure = structure
        self.params = (params if params is not None
                       else ParameterSet(list(structure.zones), extra=structure.extra_params))
        if list(self.params.zones) != list(structure.zones):
            raise ValueError(
                f"parameter zones {list(self.params.zones)} differ from model zones "
                f"{list(structure.zones)}"
            )
        self.step = float(step)
        self.method = method
        self.u_nominal = np.broadcast_to(
            np.asarray(u_nominal, dtype=float), (self.n_boxes,)
        ).copy()
        self._cache_size = cache_size or max(16, int(2.56e8 // (16 * structure.n**2)))
        self._cache: OrderedDict[bytes, tuple[np.ndarray, np.ndarray]] = OrderedDict()
        theta = self.params.physical
        self.A = structure.A(theta).toarray()
        self.Bv = structure.Bv(theta).toarray()
        self.B_ig = structure.B_ig
        self.C = structure.C
        self._bxu = structure.Bxu_diag()  # one nonzero per box: (room, room)
        self._rooms = structure.room_of_box
        nb = len(structure.boxes)
        self.reheat_scale = (np.ones(nb) if reheat_scale is None
                             else np.broadcast_to(np.asarray(reheat_scale, float), (nb,)).copy())
        if not np.all(np.isfinite(self.reheat_scale)) or np.any(self.reheat_scale < 0):
            raise ValueError(f"reheat_scale must be finite and >= 0, got {self.reheat_scale}")
        self.reheat_from_faces = bool(reheat_from_faces)
        self._rh_faces: np.ndarray | None = None  # (n, n_boxes) [1/(J/K)], built when used
        # return air into plenums: the plenum's air state and c_p / C_plenum per box (-1, 0:
        # none); the room's air enters at its value at the step's start (docs/model.md)
        self._ret, self._retc = structure.returns
        self._has_ret = bool(np.any(self._ret >= 0))
        cap = structure.capacity
        k0 = -cap[:, None] * self.A
        # K is symmetric unless a face follows another state one way (adiabatic="mirror")
        self._general = self._has_ret or not np.allclose(
            k0, k0.T, rtol=0.0, atol=1e-9 * max(1.0, float(np.abs(k0).max())))
        self._k0 = 0.5 * (k0 + k0.T)  # symmetric by construction; remove round-off
        self._sq = np.sqrt(cap)
        self._isq = 1.0 / self._sq
        self._fixed: DiscreteBilinear | None = None
        # films switched by their room's convection regime (RCStructure.switched): the
        # extra conductance dg [W/K] of each link at mode 1, with the current parameters
        sw = structure.switched
        if sw:
            self._swi = np.ascontiguousarray(sw["links"], dtype=np.int64)
            self._sw_dg = structure.switched_conductance(theta)
            self._swg = np.column_stack([self._sw_dg / cap[self._swi[:, 0]],
                                         self._sw_dg / cap[self._swi[:, 1]]])
            self._mode_col = structure.mode_of_box()
            self.n_modes = len(sw["rooms"])
        else:
            self._swi, self._swg = np.zeros((0, 3), np.int64), np.zeros((0, 2))
            self._sw_dg = np.zeros(0)
            self._mode_col = np.full(len(structure.boxes), -1, dtype=np.int64)
            self.n_modes = 0

    def with_params(self, values: Mapping[str, float] | Sequence[float] | ParameterSet) -> BilinearModel:
        """Same structure, new parameter values (cheap: A = A0 + sum theta_p A_p)."""
        params = values if isinstance(values, ParameterSet) else self.params.copy(values)
        return BilinearModel(
            self.structure, params, self.step, self.method, self.u_nominal, self._cache_size,
            self.reheat_scale, self.reheat_from_faces)

    # sizes -----------------------------------------------------------------------
    @property
    def n(self) -> int:
        return self.structure.n

    @property
    def n_boxes(self) -> int:
        return len(self.structure.boxes)

    @property
    def n_zones(self) -> int:
        return len(self.structure.zones)

    # convection regimes ----------------------------------------------------------
    @property
    def switched(self) -> tuple[np.ndarray, np.ndarray] | None:
        """The switched links as :class:`~zonecast.estimator.integrate.ExactStepper` takes
        them (``switched=``), None when the structure has none."""
        return (self._swi, self._swg) if self.n_modes else None

    def modes(self, u: np.ndarray, reheat: np.ndarray | None) -> np.ndarray | None:
        """Mode of each room's films per step ((N, n_modes) or (n_modes,), 0 or 1): 1 while
        a box of the room with airflow blows air :data:`~.rc.network.REGIME_RISE` above the
        supply air (``reheat`` [K], as :meth:`reheat_forcing`); None without switched
        links."""
        if not self.n_modes:
            return None
        u = np.asarray(u, dtype=float)
        out = np.zeros(u.shape[:-1] + (self.n_modes,))
        if reheat is None:
            return out
        on = (np.asarray(reheat, dtype=float) > REGIME_RISE) & (u > 0)
        has = self._mode_col >= 0
        if u.ndim == 1:
            out[self._mode_col[has][on[has]]] = 1.0
        else:
            rows, cols = np.nonzero(on[:, has])
            out[rows, self._mode_col[has][cols]] = 1.0
        return out

    def _mode_key(self, mode) -> bytes:
        if not self.n_modes:
            return b""
        m = np.zeros(self.n_modes) if mode is None else np.asarray(mode, dtype=float)
        return np.ascontiguousarray(m, dtype=float).tobytes()

    # continuous matrices ------------------------------------------------------
    def Bxu(self, j: int) -> np.ndarray:
        """Continuous B_xu_j [1/(s kg/s)] (paper eq:ct_model); nonzero at the room and, with a
        return plenum p, c_p / C_p at (p, room) and -c_p / C_p at (p, p)."""
        out = np.zeros((self.n, self.n))
        r = self._rooms[j]
        out[r, r] = self._bxu[j]
        p = self._ret[j]
        if p >= 0:
            out[p, r] += self._retc[j]
            out[p, p] -= self._retc[j]
        return out

    def Bvu(self, j: int) -> np.ndarray:
        """Continuous B_vu_j [1/(s kg/s)]; nonzero only at (room, Ts)."""
        out = np.zeros((self.n, len(DISTURBANCES)))
        out[self._rooms[j], 1] = -self._bxu[j]
        return out

    def system_matrix(self, u: np.ndarray, mode: np.ndarray | None = None) -> np.ndarray:
        """A + sum_j u_j B_xu_j [1/s] (return air included exactly), with the switched
        films of ``mode`` (:meth:`modes`; default every room in its usual regime)."""
        m = self.A.copy()
        u = np.asarray(u, dtype=float)
        if self.n_modes and mode is not None:
            w = np.asarray(mode, dtype=float)[self._swi[:, 2]]
            a, b = self._swi[:, 0], self._swi[:, 1]
            np.add.at(m, (a, a), -self._swg[:, 0] * w)
            np.add.at(m, (a, b), self._swg[:, 0] * w)
            np.add.at(m, (b, b), -self._swg[:, 1] * w)
            np.add.at(m, (b, a), self._swg[:, 1] * w)
        np.add.at(m, (self._rooms, self._rooms), self._bxu * u)
        if self._has_ret:
            has = self._ret >= 0
            g = self._retc[has] * u[has]
            np.add.at(m, (self._ret[has], self._rooms[has]), g)
            np.add.at(m, (self._ret[has], self._ret[has]), -g)
        return m

    def input_matrix(self, u: np.ndarray) -> np.ndarray:
        """B_v + sum_j u_j B_vu_j [K/s per unit of v]."""
        b = self.Bv.copy()
        np.add.at(b[:, 1], self._rooms, -self._bxu * np.asarray(u, dtype=float))
        return b

    def derivative(self, x, u, v, f_ig) -> np.ndarray:
        """dx/dt of paper eq:ct_model [K/s]."""
        return (
            self.system_matrix(u) @ x
            + self.input_matrix(u) @ np.asarray(v, dtype=float)
            + self.B_ig @ (self.params.c_ig + np.asarray(f_ig, dtype=float))
        )

    # exact zero-order hold -----------------------------------------------------
    def _stiffness(self, u: np.ndarray, modes: np.ndarray | None = None) -> np.ndarray:
        """Symmetric K(u) = -Cap (A + sum_j u_j B_xu_j) [W/K], stacked over rows of u, with
        the switched films of the rows of ``modes``."""
        u = np.atleast_2d(u)
        k = np.broadcast_to(self._k0, (len(u), self.n, self.n)).copy()
        d = -self.structure.capacity[self._rooms] * self._bxu * u  # c_p u_j [W/K]
        for j, r in enumerate(self._rooms):
            k[:, r, r] += d[:, j]
        if self.n_modes and modes is not None:
            g = np.atleast_2d(modes)[:, self._swi[:, 2]] * self._sw_dg  # (N, links) [W/K]
            for e, (a, b, _) in enumerate(self._swi):
                k[:, a, a] += g[:, e]
                k[:, b, b] += g[:, e]
                k[:, a, b] -= g[:, e]
                k[:, b, a] -= g[:, e]
        return k

    def _propagators(self, u: np.ndarray,
                     modes: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Exact Phi = e^{M h} and Gamma = int_0^h e^{M s} ds for rows of u (batched).

        M(u) = -Cap^-1 K(u) with K symmetric, so with S = Cap^-1/2 K Cap^-1/2 = Q L Q^T:
        e^{M h} = Cap^-1/2 Q e^{-L h} Q^T Cap^1/2 (exact, no series truncation). With return
        air, or faces that follow another state (``adiabatic="mirror"``), M(u) is not
        symmetric: :meth:`_propagators_general`.
        """
        if self._general:
            return self._propagators_general(np.atleast_2d(u), modes)
        s = self._isq[None, :, None] * self._stiffness(u, modes) * self._isq[None, None, :]
        lam, q = np.linalg.eigh(s)
        lam = np.maximum(lam, 0.0)
        h = self.step
        decay = np.exp(-lam * h)
        small = lam * h < 1e-8
        integral = np.where(small, h, -np.expm1(-lam * h) / np.where(small, 1.0, lam))
        qt_c = np.swapaxes(q, 1, 2) * self._sq[None, None, :]
        left = self._isq[None, :, None] * q
        phi = np.matmul(left * decay[:, None, :], qt_c)
        gam = np.matmul(left * integral[:, None, :], qt_c)
        return phi, gam

    def _propagators_general(self, u: np.ndarray,
                             modes: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Phi and Gamma of :meth:`_propagators` for a generator that is not symmetric (return
        air): Phi = e^{M h} by scaling and squaring (:func:`scipy.linalg.expm`) and
        Gamma = M^-1 (Phi - I) from an LU factorisation of M, which is nonsingular when every
        state has a conductive or airflow path to a boundary (outdoor air, ground, supply
        air). About 2.4x faster than an eigendecomposition for ~400 states, equal to it to
        ~1e-13 (tests/estimator/test_return_air.py); a nearly singular M (a state with no
        path to a boundary) takes the eigendecomposition (:meth:`_propagators_eig`)."""
        phis, gams = [], []
        eye = np.eye(self.n)
        h = self.step
        for i, row in enumerate(u):
            mode = None if modes is None else np.atleast_2d(modes)[i]
            m = self.system_matrix(row) if mode is None else self.system_matrix(row, mode)
            with warnings.catch_warnings():  # a singular M is handled below
                warnings.simplefilter("ignore", sla.LinAlgWarning)
                lu, piv = sla.lu_factor(m, check_finite=False)
            pivots = np.abs(np.diag(lu))
            if pivots.min() <= 1e-10 * pivots.max():
                phi, gam = self._propagators_eig(
                    row[None, :], None if mode is None else mode[None, :])
                phis.append(phi[0])
                gams.append(gam[0])
                continue
            phi = sla.expm(m * h)
            phis.append(phi)
            gams.append(sla.lu_solve((lu, piv), phi - eye, check_finite=False))
        return np.stack(phis), np.stack(gams)

    def _propagators_eig(self, u: np.ndarray,
                         modes: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Phi and Gamma of a non-symmetric generator from its eigendecomposition:
        S = Cap^1/2 M Cap^-1/2 = V diag(lam) V^-1 (nearly symmetric, well conditioned),
        e^{M h} = Cap^-1/2 V e^{lam h} V^-1 Cap^1/2, Gamma likewise with (e^{lam h} - 1) / lam
        (also right for a singular M, lam = 0 giving h)."""
        mats = np.stack([self.system_matrix(row) if modes is None
                         else self.system_matrix(row, modes[i]) for i, row in enumerate(u)])
        s = self._sq[None, :, None] * mats * self._isq[None, None, :]
        lam, vec = np.linalg.eig(s)
        inv = np.linalg.inv(vec)
        h = self.step
        z = lam * h
        small = np.abs(z) < 1e-8
        decay = np.exp(z)
        integral = np.where(small, h, np.expm1(z) / np.where(small, 1.0, lam))
        left = self._isq[None, :, None] * vec
        right = inv * self._sq[None, None, :]
        phi = np.real(np.matmul(left * decay[:, None, :], right))
        gam = np.real(np.matmul(left * integral[:, None, :], right))
        return phi, gam

    def _lookup(self, u: np.ndarray, mode: np.ndarray | None = None
                ) -> tuple[np.ndarray, np.ndarray]:
        key = np.ascontiguousarray(u, dtype=float).tobytes() + self._mode_key(mode)
        hit = self._cache.get(key)
        if hit is None:
            phi, gam = self._propagators(
                u[None, :], None if mode is None or not self.n_modes else np.atleast_2d(mode))
            hit = (phi[0], gam[0])
            self._store(key, hit)
        else:
            self._cache.move_to_end(key)
        return hit

    def _store(self, key: bytes, value) -> None:
        self._cache[key] = value
        if len(self._cache) > self._cache_size:
            self._cache.popitem(last=False)

    def _batch(self) -> int:
        return max(1, int(2e7 // (self.n * self.n)))  # ~160 MB of float64 per batch

    def _chunk_propagators(self, u: np.ndarray, modes: np.ndarray | None = None
                           ) -> dict[bytes, tuple[np.ndarray, np.ndarray]]:
        """Propagators of all distinct rows of u (with ``modes``) (cache first, the rest
        batched), keyed as :meth:`_lookup`."""
        out: dict[bytes, tuple[np.ndarray, np.ndarray]] = {}
        todo = []
        u = np.ascontiguousarray(u, dtype=float)
        both = u if not self.n_modes or modes is None else np.hstack([u, modes])
        nb = u.shape[1]
        for row in np.unique(both, axis=0):
            key = row[:nb].tobytes() + (self._mode_key(row[nb:]) if self.n_modes else b"")
            hit = self._cache.get(key)
            if hit is None:
                todo.append(row)
            else:
                out[key] = hit
        if todo:
            rows = np.array(todo)
            phi, gam = self._propagators(rows[:, :nb], rows[:, nb:] if rows.shape[1] > nb
                                         else None)
            for row, p, g in zip(rows, phi, gam):
                key = row[:nb].tobytes() + (self._mode_key(row[nb:]) if self.n_modes else b"")
                out[key] = (p, g)
                self._store(key, (p, g))
        return out

    def step_matrices(self, u: np.ndarray, mode: np.ndarray | None = None
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Exact one-step matrices for airflows u held over the step.

        Parameters
        ----------
        u : ndarray (n_boxes,)
            Airflow per box [kg/s].
        mode : ndarray (n_modes,), optional
            The rooms' convection regimes (:meth:`modes`); default the usual regime.

        Returns
        -------
        Phi : ndarray (n, n)
        Gamma_v : ndarray (n, 7)
        Gamma_ig : ndarray (n, n_zones)
            x(k+1) = Phi x + Gamma_v v + Gamma_ig (c_IG + f_IG).
        """
        u = np.asarray(u, dtype=float)
        phi, gam = self._lookup(u, mode)
        return phi, gam @ self.input_matrix(u), gam @ self.B_ig

    def reheat_step(self, u: np.ndarray, reheat: np.ndarray | None) -> np.ndarray:
        """Gamma(u) times :meth:`reheat_forcing`: the step's state increment [K] from the
        boxes' discharge air above the supply air, with u and the rise held over the step."""
        u = np.asarray(u, dtype=float)
        if reheat is None or not np.any(reheat):
            return np.zeros(self.n)
        _, gam = self._lookup(u, self.modes(u, reheat))
        return gam @ self.reheat_forcing(u, reheat)

    # paper fixed-matrix form -------------------------------------------------
    def discrete_bilinear(self) -> DiscreteBilinear:
        """Fixed matrices of paper eq:model_dt, linearised in u around ``u_nominal``."""
        if self._fixed is not None:
            return self._fixed
        n, nv, nz, nb = self.n, len(DISTURBANCES), self.n_zones, self.n_boxes
        size = n + nv + nz
        aug = np.zeros((size, size))
        aug[:n, :n] = self.system_matrix(self.u_nominal)
        aug[:n, n:n + nv] = self.input_matrix(self.u_nominal)
        aug[:n, n + nv:] = self.B_ig
        e0 = sla.expm(aug * self.step)
        bxu = np.zeros((nb, n, n))
        bvu = np.zeros((nb, n, nv))
        for j in range(nb):
            direction = np.zeros((size, size))
            r = self._rooms[j]
            direction[r, r] = self._bxu[j]
            direction[r, n + 1] = -self._bxu[j]
            if self._ret[j] >= 0:
                p = self._ret[j]
                direction[p, r] += self._retc[j]
                direction[p, p] -= self._retc[j]
            _, d = sla.expm_frechet(aug * self.step, direction * self.step)
            bxu[j] = d[:n, :n]
            bvu[j] = d[:n, n:n + nv]
        a = e0[:n, :n] - np.tensordot(self.u_nominal, bxu, axes=1)
        bv = e0[:n, n:n + nv] - np.tensordot(self.u_nominal, bvu, axes=1)
        self._fixed = DiscreteBilinear(a, bv, e0[:n, n + nv:], bxu, bvu, self.C, self.u_nominal)
        return self._fixed

    # simulation ------------------------------------------------------------------
    def reheat_forcing(self, u: np.ndarray, reheat: np.ndarray | None) -> np.ndarray:
        """Forcing [K/s] of each state by the boxes' discharge air above the supply air.

        The supply-air term of paper eq:ct_model, c_p u_j (T_s - T_room), assumes every box
        blows air at the AHU supply temperature. A box with a discharge-air point blows it
        at T_s + r_j (r_j: the reheat coil's rise, measured); the difference,
        c_p u_j r_j / C_room, is a known input added here (zero when ``reheat`` is None),
        times the box's :attr:`reheat_scale`.

        Parameters
        ----------
        u : (N, n_boxes) or (n_boxes,) airflows [kg/s]
        reheat : same shape, discharge-air rise over the supply air [K]

        Returns
        -------
        ndarray (N, n) or (n,)
        """
        u = np.asarray(u, dtype=float)
        out = np.zeros(u.shape[:-1] + (self.n,))
        if reheat is None:
            return out
        # K/s per box (bxu < 0)
        q = -self._bxu * self.reheat_scale * u * np.asarray(reheat, dtype=float)
        if u.ndim == 1:
            np.add.at(out, self._rooms, q)
        else:
            np.add.at(out.T, self._rooms, q.T)
        if self.reheat_from_faces and np.any(self.reheat_scale != 1.0):
            # the air's extra heat (scale - 1) c_p u r [W] taken from the room's faces
            out += ((self.reheat_scale - 1.0) * self.reheat_heat(u, reheat)
                    ) @ self._reheat_faces().T
        return out

    def reheat_heat(self, u: np.ndarray, reheat: np.ndarray) -> np.ndarray:
        """The measured reheat heat c_p u_j r_j of each box [W] (as measured: no
        :attr:`reheat_scale`), with the model's c_p; same shapes as ``u``."""
        return (-self.structure.capacity[self._rooms] * self._bxu * np.asarray(u, dtype=float)
                * np.asarray(reheat, dtype=float))

    def _reheat_faces(self) -> np.ndarray:
        """(n, n_boxes): minus each face's share of its box room's film conductance over
        the face's capacity [K/J]; the room air's links to states that are not air."""
        if self._rh_faces is None:
            st = self.structure
            air = np.zeros(self.n, bool)
            air[st.air_states()] = True
            cap = st.capacity
            w = np.zeros((self.n, len(self._rooms)))
            for j, r in enumerate(self._rooms):
                g = np.where(~air & (np.arange(self.n) != r), self.A[r] * cap[r], 0.0)
                g = np.clip(g, 0.0, None)
                if g.sum() > 0:
                    w[:, j] = -g / g.sum() / cap
            self._rh_faces = w
        return self._rh_faces

    def _check_inputs(self, x0, u, v, f_ig):
        u = np.atleast_2d(np.asarray(u, dtype=float))
        v = np.atleast_2d(np.asarray(v, dtype=float))
        nsteps = len(u)
        if f_ig is None:
            f_ig = np.zeros((nsteps, self.n_zones))
        f_ig = np.atleast_2d(np.asarray(f_ig, dtype=float))
        x0 = np.asarray(x0, dtype=float)
        if x0.ndim == 0:
            x0 = np.full(self.n, float(x0))
        checks = [
            ("u", u, (nsteps, self.n_boxes), "kg/s per box"),
            ("v", v, (nsteps, len(DISTURBANCES)), ", ".join(DISTURBANCES)),
            ("f_ig", f_ig, (nsteps, self.n_zones), "W/m2 per zone"),
            ("x0", x0, (self.n,), "degC per state"),
        ]
        for name, arr, shape, what in checks:
            if arr.shape != shape:
                raise ValueError(f"{name} has shape {arr.shape}; expected {shape} ({what})")
            if not np.all(np.isfinite(arr)):
                raise ValueError(f"{name} contains NaN or inf; fill gaps before simulating")
        return x0, u, v, f_ig

    def simulate(
        self,
        x0: np.ndarray | float,
        u: np.ndarray,
        v: np.ndarray,
        f_ig: np.ndarray | None = None,
        method: str | None = None,
        reheat: np.ndarray | None = None,
    ) -> SimulationResult:
        """Simulate paper eq:model_dt.

        Parameters
        ----------
        x0 : ndarray (n,) or float
            Initial states [degC] (a float sets all states).
        u : ndarray (N, n_boxes)
            Airflow per box [kg/s], held over each step.
        v : ndarray (N, 6)
            [Ta degC, Ts degC, solE, solS, solW, solN, solH W/m2].
        f_ig : ndarray (N, n_zones), optional
            Time-varying internal gains [W/m2]; default zero.
        method : {"exact", "eig", "bilinear"}, optional
            Default: the model's method.
        reheat : ndarray (N, n_boxes), optional
            Discharge-air rise over the supply air per box [K] (:meth:`reheat_forcing`);
            default none.

        Returns
        -------
        SimulationResult
        """
        x0, u, v, f_ig = self._check_inputs(x0, u, v, f_ig)
        if reheat is not None:
            reheat = np.atleast_2d(np.asarray(reheat, dtype=float))
            if reheat.shape != u.shape:
                raise ValueError(f"reheat has shape {reheat.shape}; expected {u.shape} "
                                 "(K per box)")
            if not np.all(np.isfinite(reheat)):
                raise ValueError("reheat contains NaN or inf; fill gaps before simulating")
            if not np.any(reheat):
                reheat = None
        method = method or self.method
        nsteps = len(u)
        xs = np.empty((nsteps + 1, self.n))
        xs[0] = x0
        gains = f_ig + self.params.c_ig
        x = x0
        extra = self.reheat_forcing(u, reheat) if reheat is not None else 0.0
        modes = self.modes(u, reheat)
        if method == "exact":
            forcing = v @ self.Bv.T + gains @ self.B_ig.T + extra
            xs = simulate_exact(self.structure.A(self.params.physical), self._rooms, self._bxu,
                                x0, u, forcing, v[:, 1], self.step,
                                capacity=self.structure.capacity, ret=self._ret,
                                retc=self._retc, switched=self.switched, modes=modes)
        elif method == "eig":
            forcing = v @ self.Bv.T + gains @ self.B_ig.T + extra  # u held per step
            ts = v[:, 1]
            props: dict[bytes, tuple[np.ndarray, np.ndarray]] = {}
            for k in range(nsteps):
                if k % self._batch() == 0:
                    props = self._chunk_propagators(
                        u[k:k + self._batch()],
                        None if modes is None else modes[k:k + self._batch()])
                phi, gam = props[np.ascontiguousarray(u[k]).tobytes()
                                 + (b"" if modes is None else self._mode_key(modes[k]))]
                w = forcing[k].copy()
                np.add.at(w, self._rooms, -self._bxu * u[k] * ts[k])  # B_vu_j v u_j
                x = phi @ x + gam @ w
                xs[k + 1] = x
        elif method == "bilinear":
            d = self.discrete_bilinear()
            if self.n_modes:
                raise ValueError("the 'bilinear' method (paper's fixed matrices) has no "
                                 "convection regimes; simulate with method='exact'")
            if reheat is not None:
                raise ValueError("the 'bilinear' method (paper's fixed matrices) has no "
                                 "discharge-air input; simulate with method='exact'")
            lin = v @ d.Bv.T + gains @ d.B_ig.T
            for k in range(nsteps):
                m = d.A + np.tensordot(u[k], d.Bxu, axes=1)
                x = m @ x + lin[k] + np.tensordot(u[k], d.Bvu, axes=1) @ v[k]
                xs[k + 1] = x
        else:
            raise ValueError(f"method must be one of {METHODS}")
        return SimulationResult(xs, xs @ self.C.T)

    def steady_state(self, u: np.ndarray, v: np.ndarray, f_ig: np.ndarray | None = None) -> np.ndarray:
        """States [degC] at equilibrium for constant u, v, f_ig (solves dx/dt = 0)."""
        u = np.asarray(u, dtype=float)
        v = np.asarray(v, dtype=float)
        f_ig = np.zeros(self.n_zones) if f_ig is None else np.asarray(f_ig, dtype=float)
        rhs = self.input_matrix(u) @ v + self.B_ig @ (self.params.c_ig + f_ig)
        return np.linalg.solve(self.system_matrix(u), -rhs)

    # labels ------------------------------------------------------------------------
    def state_zones(self) -> np.ndarray:
        """Model-zone index of every state (-1 for states of rooms in no model zone);
        :meth:`RCStructure.state_zones`."""
        return self.structure.state_zones()

    def room_weights(self) -> dict[str, float]:
        """Weight of each room's air temperature in its zone's output (row of C)."""
        out = {}
        for i, lab in enumerate(self.structure.labels):
            if lab.kind == "room_air":
                out[lab.room] = float(self.C[:, i].max())
        return out

    # reporting -----------------------------------------------------------------
    def summary(self) -> dict:
        """JSON-ready description: states by kind, rooms, zones, boxes, parameters."""
        s = self.structure
        return {
            "schema_version": 1,
            "n_states": s.n,
            "states_by_kind": s.state_counts(),
            "rooms": s.rooms,
            "zones": s.zones,
            "boxes": s.boxes,
            "disturbances": list(DISTURBANCES),
            "step_s": self.step,
            "method": self.method,
            "parameters": self.params.as_dict(),
            "exterior_areas_m2": s.areas,
            "output_weighting": "C: air-volume-weighted mean of each zone's rooms",
            "notes": s.notes,
            "state_labels": [str(label) for label in s.labels],
        }


def build_model(
    building: Building,
    zones: Mapping[str, Sequence[str]],
    boxes: Mapping[str, str],
    params: ParameterSet | Mapping[str, float] | Sequence[float] | None = None,
    options: ModelOptions | None = None,
    **kwargs,
) -> BilinearModel:
    """Build the bilinear RC model from plain data.

    Parameters
    ----------
    building : Building
        From :func:`zonecast.estimator.idf.read_building`.
    zones : mapping
        Model zone -> EnergyPlus zone names (case-insensitive).
    boxes : mapping
        VAV box id -> room (EnergyPlus zone name) it serves.
    params : ParameterSet, mapping or vector, optional
        Parameter values; default the physical starting values.
    options : ModelOptions, optional
    **kwargs
        ``step`` [s], ``method``, ``u_nominal`` [kg/s] of :class:`BilinearModel`.

    Returns
    -------
    BilinearModel
    """
    structure = build_structure(building, zones, boxes, options)
    if params is not None and not isinstance(params, ParameterSet):
        params = ParameterSet(list(structure.zones), params, structure.extra_params)
    return BilinearModel(structure, params, **kwargs)


__all__.append("build_model")


def write_model_summary(model: BilinearModel, out_json: str | Path, out_npz: str | Path) -> None:
    """Write the model description (JSON) and its matrices (.npz).

    The .npz holds the continuous A, B_v, B_IG, C, the per-box B_xu_j/B_vu_j
    nonzeros (room index, value), state capacities, and the exact discrete
    matrices at zero airflow (``Phi0``, ``Gamma_v0``, ``Gamma_ig0``).
    """
    summary = model.summary()
    Path(out_json).write_text(json.dumps(summary, indent=2))
    phi, gv, gig = model.step_matrices(np.zeros(model.n_boxes))
    np.savez_compressed(
        out_npz,
        A=model.A, Bv=model.Bv, B_ig=model.B_ig, C=model.C,
        Bxu_room=model.structure.room_of_box, Bxu_value=model.structure.Bxu_diag(),
        capacity=model.structure.capacity, Phi0=phi, Gamma_v0=gv, Gamma_ig0=gig,
        step=model.step, labels=np.array(summary["state_labels"]),
        param_names=np.array(model.params.param_names), param_values=model.params.values,
    )
