"""Building elements: constructions discretised into a few capacitive nodes.

BRCM-like lumping (paper section sec:model, footnote: "each wall, floor and
ceiling is decomposed into 2 to 3 BEs"): the layers of a construction are
placed on a *resistance coordinate* r in [0, R_total] (0 = outside face). Two
nodes sit on the faces; a third, middle node is added for massive multi-layer
constructions at the capacity centroid. Each layer's heat capacity is shared
among the nodes with linear (hat) weights in r, so thin layers are grouped with
their neighbours automatically; the conduction resistance between neighbouring
nodes is the resistance between their positions (pure-resistance layers such
as Material:NoMass and Material:AirGap simply add resistance).

Putting nodes on the faces makes every film conductance exactly gamma * area,
so the model matrices are affine in each gamma (see ``docs/model.md``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from zonecast.estimator.idf import Layer

__all__ = ["ADMITTANCE_TOLERANCE", "FINE_SECTION_TIME", "MASSLESS_FACE_CAPACITY",
           "MIN_RESISTANCE", "NodeLayout", "admittance_error", "discretise_layers",
           "inside_admittance", "layout_admittance"]

#: Areal capacity given to each face node of a construction without mass [J/(m2 K)]
#: (about 2 mm of gypsum): keeps the state equation regular; documented in docs/model.md.
MASSLESS_FACE_CAPACITY = 2.0e3
#: Smallest total construction resistance accepted [m2 K/W].
MIN_RESISTANCE = 1.0e-3
#: A single massive layer above this areal capacity gets a middle node [J/(m2 K)].
THICK_LAYER_CAPACITY = 1.0e5
#: Smallest total resistance for a three-node element [m2 K/W].
MIN_THREE_NODE_RESISTANCE = 0.04
#: Longest diffusion time R_k C_k of one section between neighbouring nodes [s] when a
#: construction is resolved finely (``discretise_layers(..., section_time=...)``).
FINE_SECTION_TIME = 3600.0
#: Period of the periodic admittance that judges a lumped layout [s]: the day.
ADMITTANCE_PERIOD = 86400.0
#: Exterior film behind a face open to the outdoors when its admittance is judged
#: [W/(m2 K)] (the handbook's combined exterior film, EN ISO 6946's 1/0.04).
ADMITTANCE_OUTER_FILM = 25.0
#: Largest relative error of a lumped layout's daily inside admittance |Y| that
#: ``ModelOptions(layers="admittance_but_facades")`` (and ``"roofs_admittance"``) accepts
#: before resolving a construction finely [-].
ADMITTANCE_TOLERANCE = 0.10


@dataclass(frozen=True)
class NodeLayout:
    """Discretisation of one construction, per unit area.

    Attributes
    ----------
    positions : ndarray
        Node positions on the resistance coordinate [m2 K/W], outside face first.
    capacities : ndarray
        Areal heat capacity of each node [J/(m2 K)].
    resistances : ndarray
        Resistance between neighbouring nodes [m2 K/W] (len(positions) - 1).
    """

    positions: np.ndarray
    capacities: np.ndarray
    resistances: np.ndarray

    @property
    def n(self) -> int:
        return len(self.positions)

    @property
    def resistance(self) -> float:
        """Face-to-face resistance [m2 K/W]."""
        return float(self.positions[-1] - self.positions[0])


def _hat_share(a: float, b: float, p0: float, p1: float) -> tuple[float, float]:
    """Integral over [a, b] (inside [p0, p1]) of the two hat weights, per unit density."""
    w = p1 - p0
    # integral of (p1 - r)/w and (r - p0)/w over [a, b]
    left = ((p1 - a) ** 2 - (p1 - b) ** 2) / (2 * w)
    right = ((b - p0) ** 2 - (a - p0) ** 2) / (2 * w)
    return left, right


def _fine_positions(res: np.ndarray, cap: np.ndarray, edges: np.ndarray,
                    section_time: float) -> np.ndarray | None:
    """Node positions [m2 K/W] that cut a construction into sections of equal diffusion time.

    A layer of resistance R and capacity C takes about R C to pass a step through; on the
    coordinate q = sum sqrt(R_i C_i) [s^0.5] (massless layers have no length) sections of
    equal length have equal R_k C_k, and n = ceil(Q / sqrt(section_time)) of them keep each
    at most ``section_time``. Returns None when two sections or fewer would do.
    """
    length = np.sqrt(np.maximum(res * cap, 0.0))
    total = float(length.sum())
    n = int(np.ceil(total / np.sqrt(section_time)))
    if n <= 2:
        return None
    q_edges = np.concatenate([[0.0], np.cumsum(length)])
    r_total = float(edges[-1])
    pos = [0.0]
    for k in range(1, n):
        target = k * total / n
        i = int(np.searchsorted(q_edges, target, side="left")) - 1
        i = min(max(i, 0), len(length) - 1)  # q_edges[i] < target <= q_edges[i+1]: massive
        frac = (target - q_edges[i]) / length[i]
        r = float(edges[i] + min(max(frac, 0.0), 1.0) * res[i])
        if r - pos[-1] > 1e-6 * r_total and r_total - r > 1e-6 * r_total:
            pos.append(r)
    pos.append(r_total)
    return np.array(pos)


def discretise_layers(layers: Sequence[Layer], section_time: float | None = None) -> NodeLayout:
    """Lump a construction (outside layer first) into 2 or 3 nodes, or resolve it finely.

    Parameters
    ----------
    layers : sequence of Layer
        Outside to inside.
    section_time : float, optional
        If given [s], constructions whose layers add up to more than two sections of this
        diffusion time get one node per section (:func:`_fine_positions`); others keep the
        2- or 3-node lumping.

    Returns
    -------
    NodeLayout
    """
    res = np.array([max(layer.resistance, 0.0) for layer in layers], dtype=float)
    cap = np.array([layer.heat_capacity for layer in layers], dtype=float)
    r_total = max(float(res.sum()), MIN_RESISTANCE)
    if res.sum() < MIN_RESISTANCE:  # scale a degenerate construction up to the minimum
        res = np.full(max(len(layers), 1), r_total / max(len(layers), 1))
        cap = cap if len(cap) else np.zeros(1)
    edges = np.concatenate([[0.0], np.cumsum(res)])
    massive = int((cap > 0).sum())
    c_total = float(cap.sum())
    if c_total <= 0:
        return NodeLayout(
            np.array([0.0, r_total]), np.full(2, MASSLESS_FACE_CAPACITY), np.array([r_total])
        )
    three = r_total >= MIN_THREE_NODE_RESISTANCE and (
        massive >= 2 or c_total >= THICK_LAYER_CAPACITY
    )
    fine = None if section_time is None else _fine_positions(res, cap, edges, section_time)
    if fine is not None:
        pos = fine
    elif three:
        centres = 0.5 * (edges[:-1] + edges[1:])
        mid = float(np.dot(cap, centres) / c_total)
        mid = min(max(mid, 0.25 * r_total), 0.75 * r_total)
        pos = np.array([0.0, mid, r_total])
    else:
        pos = np.array([0.0, r_total])
    node_cap = np.zeros(len(pos))
    for k in range(len(pos) - 1):
        p0, p1 = pos[k], pos[k + 1]
        for i in range(len(res)):
            a, b = max(edges[i], p0), min(edges[i + 1], p1)
            if b <= a or res[i] <= 0:
                continue
            density = cap[i] / res[i]
            left, right = _hat_share(a, b, p0, p1)
            node_cap[k] += density * left
            node_cap[k + 1] += density * right
    # layers of zero resistance but with mass cannot exist (R = d/k > 0); keep totals exact
    node_cap *= c_total / node_cap.sum()
    # a node between massless layers only (the outer face of an F- or C-factor construction:
    # EnergyPlus's fictitious insulation outside its concrete) gets a massless face's
    # capacity, as a construction without mass does: a state needs a capacity
    node_cap[node_cap <= 0] = MASSLESS_FACE_CAPACITY
    return NodeLayout(pos, node_cap, np.diff(pos))


# --------------------------------------------------------------------------- admittance
def _layer_matrix(resistance: float, capacity: float, omega: float) -> np.ndarray:
    """Transfer matrix of one homogeneous layer (EN ISO 13786 eq. 4, in R and C per area):
    (theta, q) on its inner side from those on its outer side, q flowing outwards."""
    r = max(resistance, 0.0)
    if capacity <= 0 or r <= 0:
        return np.array([[1.0, r], [0.0, 1.0]], dtype=complex)
    xi = np.sqrt(1j * omega * r * capacity)
    return np.array([[np.cosh(xi), r * np.sinh(xi) / xi],
                     [xi * np.sinh(xi) / r, np.cosh(xi)]])


def _admittance(m: np.ndarray, outer_film: float | None) -> complex:
    if outer_film is None:  # no flux through the outer face
        return complex(m[1, 0] / m[0, 0])
    return complex((m[1, 0] + m[1, 1] * outer_film) / (m[0, 0] + m[0, 1] * outer_film))


def inside_admittance(layers: Sequence[Layer], outer_film: float | None = ADMITTANCE_OUTER_FILM,
                      period: float = ADMITTANCE_PERIOD) -> complex:
    """Periodic admittance of a construction's inside face, exact (EN ISO 13786).

    The heat flux into the inside face per unit amplitude of its temperature [W/(m2 K)]
    at ``period`` [s], with the outer face held through ``outer_film`` [W/(m2 K)] to a
    steady temperature, or adiabatic (``None``); no inside film.
    """
    omega = 2.0 * np.pi / period
    m = np.eye(2, dtype=complex)
    for layer in reversed(list(layers)):  # inside layer first
        m = m @ _layer_matrix(layer.resistance, layer.heat_capacity, omega)
    return _admittance(m, outer_film)


def layout_admittance(layout: NodeLayout, outer_film: float | None = ADMITTANCE_OUTER_FILM,
                      period: float = ADMITTANCE_PERIOD) -> complex:
    """The same admittance [W/(m2 K)] of a node layout (the RC ladder the model builds)."""
    omega = 2.0 * np.pi / period
    m = np.eye(2, dtype=complex)
    for k in range(layout.n - 1, -1, -1):  # inside node first
        m = m @ np.array([[1.0, 0.0], [1j * omega * layout.capacities[k], 1.0]])
        if k > 0:
            m = m @ np.array([[1.0, layout.resistances[k - 1]], [0.0, 1.0]], dtype=complex)
    return _admittance(m, outer_film)


def admittance_error(layers: Sequence[Layer], layout: NodeLayout,
                     outer_film: float | None = ADMITTANCE_OUTER_FILM) -> float:
    """Relative error of ``layout``'s daily inside |Y| against the exact construction [-]."""
    exact = abs(inside_admittance(layers, outer_film))
    return abs(layout_admittance(layout, outer_film)) / exact - 1.0
