"""The service-only environment of tests/test_serve_without_energyplus.py (a fresh venv with
``pip install zonecast[service]``, about a minute), started by tests/conftest.py as soon as
that test is selected: it builds on the second core while the rest of the suite, which is
single-threaded, runs."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
#: (folder, process) of the build started for this session
BUILD_KEY = pytest.StashKey[tuple]()


#: what the build's copy of the project leaves out (environments, outputs, caches)
#: (``.hypothesis``: another xdist worker writes its temporary files while this copies, a race
#: that failed one collection with "No such file or directory")
_NOT_SOURCES = shutil.ignore_patterns(".venv", ".git", "runs", "build", "demo-out", "*.egg-info",
                                      "__pycache__", ".pytest_cache", ".ruff_cache",
                                      ".hypothesis", "node_modules")


def build_venv(folder: Path) -> subprocess.Popen:
    """Start building the environment in ``folder / "venv"`` (log in ``build.log``) from a
    copy of the project's sources in ``folder / "src"``: with pytest-xdist every worker
    starts a build, and two pip builds of one source tree share its ``build/`` folder
    (a race that failed one build with "Directory not empty")."""
    venv, src = folder / "venv", folder / "src"
    shutil.copytree(ROOT, src, ignore=_NOT_SOURCES)
    script = (f'"{sys.executable}" -m venv "{venv}" && '
              f'"{venv}/bin/python" -m pip install --quiet "{src}[service]"')
    with (folder / "build.log").open("w") as log:
        return subprocess.Popen(["/bin/sh", "-c", script], stdout=log, stderr=subprocess.STDOUT,
                                start_new_session=True)  # one process group: killed together


def start_background_build(config) -> None:
    """Start the build; it is stopped and removed when the session ends (also when the test
    never ran, e.g. with ``--collect-only``)."""
    folder = Path(tempfile.mkdtemp(prefix="zonecast-serve-only-"))
    proc = build_venv(folder)
    config.stash[BUILD_KEY] = (folder, proc)

    def cleanup() -> None:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
        shutil.rmtree(folder, ignore_errors=True)

    config.add_cleanup(cleanup)
