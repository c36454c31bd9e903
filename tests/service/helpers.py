"""Small helpers shared by the service tests (not fixtures: plain functions)."""

from __future__ import annotations

import time

import pandas as pd


def body_of(row: pd.Series, drop=()) -> dict:
    """A telemetry row as the map-form message body, empty cells and ``drop`` left out."""
    return {"time": row["time"],
            "readings": {k: float(v) for k, v in row.items()
                         if k != "time" and k not in drop and pd.notna(v)}}


def wait_until(cond, timeout: float = 60.0, what: str = "condition") -> None:
    """Poll ``cond`` every 50 ms until it holds; AssertionError after ``timeout`` [s]."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if cond():
            return
        time.sleep(0.05)
    raise AssertionError(f"timed out waiting for {what}")
