"""Units accepted in a site's point map and their conversion to SI (degC, kg/s, W/m2, W, and
the cloud cover as a fraction 1)."""

from __future__ import annotations

import numpy as np

#: density of standard air used to turn volume flow into mass flow [kg/m3]
STANDARD_AIR_DENSITY = 1.2

# unit -> (quantity, function converting an array to the SI unit of the quantity)
_CONVERSIONS = {
    "degC": ("temperature", lambda a: a),
    "degF": ("temperature", lambda a: (a - 32.0) * 5.0 / 9.0),
    "K": ("temperature", lambda a: a - 273.15),
    "kg/s": ("airflow", lambda a: a),
    "m3/s": ("airflow", lambda a: a * STANDARD_AIR_DENSITY),
    "L/s": ("airflow", lambda a: a * 1e-3 * STANDARD_AIR_DENSITY),
    "cfm": ("airflow", lambda a: a * 0.3048**3 / 60.0 * STANDARD_AIR_DENSITY),
    "W/m2": ("irradiance", lambda a: a),
    "kW/m2": ("irradiance", lambda a: a * 1e3),
    "W": ("power", lambda a: a),
    "kW": ("power", lambda a: a * 1e3),
    # the share of the sky covered by (opaque) cloud, as weather services and stations give
    # it: a fraction, a percentage, eighths (oktas, METAR) or tenths (EPW weather files)
    "1": ("cloud_cover", lambda a: a),
    "%": ("cloud_cover", lambda a: a / 100.0),
    "okta": ("cloud_cover", lambda a: a / 8.0),
    "tenths": ("cloud_cover", lambda a: a / 10.0),
}

SI_UNIT = {"temperature": "degC", "airflow": "kg/s", "irradiance": "W/m2", "power": "W",
           "cloud_cover": "1"}


def units_for(quantity: str) -> list[str]:
    """Units accepted for a quantity (temperature, airflow, irradiance, power,
    cloud_cover)."""
    return [u for u, (q, _) in _CONVERSIONS.items() if q == quantity]


def check_unit(unit: str, quantity: str) -> str:
    """Return ``unit`` if it measures ``quantity``, else raise ValueError naming the choices."""
    if unit not in _CONVERSIONS or _CONVERSIONS[unit][0] != quantity:
        raise ValueError(f"unit {unit!r} is not a {quantity} unit; use one of {units_for(quantity)}")
    return unit


def to_si(values: np.ndarray, unit: str) -> np.ndarray:
    """Convert ``values`` in ``unit`` to the SI unit of its quantity."""
    if unit not in _CONVERSIONS:
        raise ValueError(f"unknown unit {unit!r}; known units: {sorted(_CONVERSIONS)}")
    return _CONVERSIONS[unit][1](np.asarray(values, dtype=float))
