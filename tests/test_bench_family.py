"""benchmarks/bench_family.py's summary: the musts' group (held out and third party
together), the must lines it prints, and its figure."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def bench():
    spec = importlib.util.spec_from_file_location("bench_family",
                                                  ROOT / "benchmarks" / "bench_family.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _row(name, role, t, v, f, r=0.95):
    return {"name": name, "role": role, "training": t, "validation": v, "fixed": f,
            "dayahead": None, "service": None, "gains_r_median": r, "gains_r_min": r,
            "coverage_service": None, "at_bounds": [], "identification_s": 1.0}


def test_the_musts_are_judged_on_held_out_and_third_party_together(bench, tmp_path):
    rows = [_row("t1", "train", 0.10, 0.10, 0.10),
            _row("h1", "heldout", 0.20, 0.20, 0.20), _row("h2", "heldout", 0.22, 0.24, 0.26),
            _row("n1", "third_party", 0.24, 0.40, 0.45, r=0.80)]
    summ = bench.summary(rows)
    assert set(summ) == {"train", "heldout", "third_party", bench.MUSTS_GROUP}
    pooled = summ[bench.MUSTS_GROUP]
    assert pooled["n"] == 3
    assert pooled["fixed"] == {"median": 0.26, "worst": 0.45}
    assert pooled["gains_r_median"]["median"] == pytest.approx(0.95)
    lines = bench.musts(summ)
    assert all(line.startswith(bench.MUSTS_GROUP) for line in lines)
    assert "median 0.260 (must <= 0.35) met; worst 0.450 (must <= the paper's 0.485) met" \
        in lines[2]
    # a third-party building beyond the paper's validation figure fails the worst must
    rows.append(_row("n2", "third_party", 0.20, 0.45, 0.30))
    lines = bench.musts(bench.summary(rows))
    assert "worst 0.450 (must <= the paper's 0.413) NOT met" in lines[1]
    assert "NOT met" not in lines[0]
    md = bench.markdown(rows, bench.summary(rows))
    assert f"| {bench.MUSTS_GROUP} | 4 |" in md and "NOT met" in md
    png = bench.plot(rows, tmp_path / "family.png")
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_without_third_party_buildings_the_held_out_ones_are_judged(bench):
    summ = bench.summary([_row("h1", "heldout", 0.30, 0.20, 0.20)])
    assert bench.MUSTS_GROUP not in summ
    lines = bench.musts(summ)
    assert lines[0].startswith("heldout training: median 0.300 (must <= 0.25) NOT met")
    assert bench.musts({"train": summ["heldout"]}) == ["musts: no heldout buildings in this run"]
