"""Benchmark: reading EnergyPlus files into a Building, with the parts EnergyPlus derives.

For each file, in one run (median of ``--repeat``):

- ``convert``: EnergyPlus's own IDF -> epJSON conversion (``load_epjson``), the reference:
  every read pays it;
- ``interpret``: the epJSON interpreted into a Building (``building_from_epjson``), with the
  rectangular surfaces turned into vertices (F/C-factor layers built beforehand, untimed);
- ``read``: the whole ``read_building``, i.e. the above plus EnergyPlus's rating runs when
  the file has layered glazing (glass U-factor and SHGC) or F/C-factor constructions.

Prints one row per file and what EnergyPlus derived; nothing is written.

    python benchmarks/bench_read.py FILE.idf [FILE.idf ...] [--repeat 3]
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import platform
import statistics
import time
from pathlib import Path

from zonecast.estimator.idf import (
    _with_fc_layers,
    building_from_epjson,
    load_epjson,
    read_building,
)


def _median_time(fn, repeat: int) -> tuple[float, object]:
    times, out = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("files", nargs="+", type=Path)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    print(f"# {platform.machine()}, {os.cpu_count()} cores, load {os.getloadavg()[0]:.2f}")
    print("| file | convert (reference) [s] | interpret [s] | read_building [s] | derived by "
          "EnergyPlus |")
    print("|---|---|---|---|---|")
    for path in args.files:
        t_conv, (data, notes) = _median_time(lambda p=path: load_epjson(p), args.repeat)
        data = _with_fc_layers(data, list(notes), None)  # F/C layers: timed in read_building
        t_int, _ = _median_time(lambda d=data, n=notes: building_from_epjson(d, list(n)),
                                args.repeat)
        t_read, b = _median_time(lambda p=path: read_building(p), args.repeat)
        derived = [n.split(":")[0] for n in b.notes
                   if "rated by EnergyPlus" in n or "as EnergyPlus builds" in n]
        print(f"| {path.name} | {t_conv:.2f} | {t_int:.3f} | {t_read:.2f} | "
              f"{'; '.join(derived) or '-'} |")


if __name__ == "__main__":
    main()
