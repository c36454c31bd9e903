"""The 13 tuning parameters of paper Table 1 (tab:param), generalised to any zone count.

Names, units, bounds and physically plausible starting values; the values the
paper identified for Sutardja Dai Hall are kept as the named reference set
:data:`PAPER_TABLE1`. The interface follows statsmodels: ``param_names``,
``start_params`` and ``bounds``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

__all__ = ["EXTRA", "PAPER_TABLE1", "PHYSICAL", "ParameterSet", "ParameterSpec"]


@dataclass(frozen=True)
class ParameterSpec:
    """One model parameter.

    Attributes
    ----------
    name : str
        Machine name (``gamma_EW``, ``c_IG[NW]``, ...).
    symbol : str
        The paper's symbol.
    description : str
    unit : str
    lower, upper : float
        Bounds for identification.
    start : float
        Physically plausible starting value.
    source : str
        Where the starting value comes from.
    """

    name: str
    symbol: str
    description: str
    unit: str
    lower: float
    upper: float
    start: float
    source: str


_GAMMA_MIN = 1e-3  # gamma > 0 (a film coefficient of zero would disconnect an element)

#: The seven building parameters shared by all zones (paper Table 1, first rows).
PHYSICAL: tuple[ParameterSpec, ...] = (
    ParameterSpec(
        "gamma_EW", "γ_EW", "exterior wall convection coefficient", "W/(m2 K)", _GAMMA_MIN, 200.0,
        25.0, "ASHRAE Fundamentals 2017 ch. 26: outside film 1/R_o = 22.7-34 W/m2K (wind 3.4-6.7 m/s)",
    ),
    ParameterSpec(
        "gamma_IW", "γ_IW", "interior wall convection coefficient", "W/(m2 K)", _GAMMA_MIN, 200.0,
        8.3, "ASHRAE Fundamentals ch. 26: still-air vertical surface film (conv.+rad.) 8.29 W/m2K",
    ),
    ParameterSpec(
        "gamma_floor", "γ_floor", "floor convection coefficient", "W/(m2 K)", _GAMMA_MIN, 200.0,
        6.1, "ASHRAE Fundamentals ch. 26: horizontal surface, heat flow down, 6.13 W/m2K",
    ),
    ParameterSpec(
        "gamma_ceil", "γ_ceil", "ceiling convection coefficient", "W/(m2 K)", _GAMMA_MIN, 200.0,
        9.3, "ASHRAE Fundamentals ch. 26: horizontal surface, heat flow up, 9.26 W/m2K",
    ),
    ParameterSpec(
        "gamma_absorp", "γ_absorp", "exterior wall solar absorption coefficient", "-", 0.0, 1.0,
        0.6, "typical solar absorptance of medium-coloured opaque facades (0.5-0.7)",
    ),
    ParameterSpec(
        "gamma_winSolAbs", "γ_winSolAbs", "window solar absorption coefficient", "-", 0.0, 1.0,
        0.4, "SHGC of common double glazing (0.25-0.7); fraction of facade irradiance reaching air",
    ),
    ParameterSpec(
        "U_win", "U_win", "window heat transmission coefficient", "W/(m2 K)", _GAMMA_MIN, 10.0,
        2.8, "ASHRAE Fundamentals ch. 15: double glazing in aluminium frame with break ~2.8-3.4",
    ),
)

#: Matrix parameters a structure may add to the seven (``RCStructure.extra_params``), after
#: them in the vector, by name. ``gamma_roof``: the outside film of the roofs
#: (``ModelOptions.roof_exterior="own"``), which the paper's one exterior film gamma_EW
#: shares with the walls; a building without roofs open to the outdoors has no such
#: parameter.
EXTRA: dict[str, ParameterSpec] = {
    "gamma_roof": ParameterSpec(
        "gamma_roof", "γ_roof", "roof exterior film coefficient", "W/(m2 K)", _GAMMA_MIN, 200.0,
        25.0, "ASHRAE Fundamentals 2017 ch. 26: outside film 1/R_o = 22.7-34 W/m2K (as γ_EW)",
    ),
}

_C_IG = {
    "symbol": "c_IG", "description": "background heat gain", "unit": "W/m2", "lower": -50.0, "upper": 100.0,
    "start": 5.0, "source": "idle office equipment and lighting ~2-10 W/m2 (ASHRAE 90.1 / ch. 18)",
}

#: Paper Table 1 (Sutardja Dai Hall, 4th floor): the identified values.
PAPER_TABLE1: dict[str, float] = {
    "gamma_EW": 10.5, "gamma_IW": 29.4, "gamma_floor": 51.5, "gamma_ceil": 44.3,
    "gamma_absorp": 0.75, "gamma_winSolAbs": 0.03, "U_win": 0.63,
    "c_IG[NW]": 0.3, "c_IG[W]": 8.0, "c_IG[S]": 18.8, "c_IG[E]": 8.0, "c_IG[NE]": 11.0,
    "c_IG[C]": 8.0,
}


class ParameterSet:
    """Parameters of a site: the seven building parameters, the structure's extra matrix
    parameters (:data:`EXTRA`, none for the paper's model), then one c_IG per model zone.

    Parameters
    ----------
    zones : sequence of str
        Model zone names, in model order.
    values : mapping or sequence, optional
        Values by name or as a vector in :attr:`param_names` order; defaults to
        :attr:`start_params`.
    extra : sequence of str, optional
        Names of extra matrix parameters (keys of :data:`EXTRA`), in the structure's order
        (:attr:`~zonecast.estimator.rc.network.RCStructure.extra_params`).
    """

    def __init__(self, zones: Sequence[str], values: Mapping[str, float] | Sequence[float] | None = None,
                 extra: Sequence[str] = ()):
        self.zones = tuple(zones)
        unknown = [e for e in extra if e not in EXTRA]
        if unknown:
            raise ValueError(f"unknown extra parameters {unknown}; known: {', '.join(EXTRA)}")
        self.extra = tuple(extra)
        self.specs: tuple[ParameterSpec, ...] = PHYSICAL + tuple(
            EXTRA[e] for e in self.extra) + tuple(
            ParameterSpec(f"c_IG[{z}]", **_C_IG) for z in self.zones
        )
        self.values = self.start_params.copy()
        if values is not None:
            self.update(values)

    # statsmodels-like ---------------------------------------------------------
    @property
    def param_names(self) -> list[str]:
        """Parameter names in vector order."""
        return [s.name for s in self.specs]

    @property
    def units(self) -> list[str]:
        return [s.unit for s in self.specs]

    @property
    def start_params(self) -> np.ndarray:
        """Physically plausible starting values."""
        return np.array([s.start for s in self.specs])

    @property
    def bounds(self) -> list[tuple[float, float]]:
        """(lower, upper) per parameter."""
        return [(s.lower, s.upper) for s in self.specs]

    @property
    def n_physical(self) -> int:
        """Number of parameters that enter the matrices (the c_IG enter the input)."""
        return len(PHYSICAL) + len(self.extra)

    # values -------------------------------------------------------------------
    def update(self, values: Mapping[str, float] | Sequence[float]) -> ParameterSet:
        """Set values (by name, or a full vector) and check the bounds; returns self."""
        new = self.values.copy()
        if isinstance(values, Mapping):
            index = {n.lower(): i for i, n in enumerate(self.param_names)}
            for name, val in values.items():
                i = index.get(str(name).lower())
                if i is None:
                    raise ValueError(
                        f"unknown parameter {name!r}; known: {', '.join(self.param_names)}"
                    )
                new[i] = float(val)
        else:
            vec = np.asarray(values, dtype=float)
            if vec.shape != new.shape:
                raise ValueError(
                    f"expected {len(new)} parameter values ({', '.join(self.param_names)}), "
                    f"got shape {vec.shape}"
                )
            new = vec.copy()
        for spec, val in zip(self.specs, new):
            if not np.isfinite(val) or not spec.lower <= val <= spec.upper:
                raise ValueError(
                    f"parameter {spec.name} = {val} is outside its bounds "
                    f"[{spec.lower}, {spec.upper}] {spec.unit}"
                )
        self.values = new
        return self

    def copy(self, values: Mapping[str, float] | Sequence[float] | None = None) -> ParameterSet:
        out = ParameterSet(self.zones, self.values, self.extra)
        if values is not None:
            out.update(values)
        return out

    @classmethod
    def paper_table1(cls) -> ParameterSet:
        """The paper's identified values for its six zones NW, W, S, E, NE, C."""
        return cls(["NW", "W", "S", "E", "NE", "C"], PAPER_TABLE1)

    @property
    def physical(self) -> np.ndarray:
        """The matrix parameters [gamma_EW, ..., U_win, then the extra ones]."""
        return self.values[: self.n_physical]

    @property
    def c_ig(self) -> np.ndarray:
        """Background gains per model zone [W/m2]."""
        return self.values[self.n_physical:]

    def __getitem__(self, name: str) -> float:
        return float(self.values[self.param_names.index(name)])

    def as_dict(self) -> dict[str, dict]:
        """Name -> {value, unit, lower, upper, description} (JSON-ready)."""
        return {
            s.name: {"value": float(v), "unit": s.unit, "lower": s.lower, "upper": s.upper,
                     "description": s.description, "symbol": s.symbol}
            for s, v in zip(self.specs, self.values)
        }

    def __repr__(self) -> str:
        body = ", ".join(f"{n}={v:.4g}" for n, v in zip(self.param_names, self.values))
        return f"ParameterSet({body})"
