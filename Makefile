# zonecast — the README's first two commands are `make demo` and `make test`.
PYTHON ?= $(shell for p in python3.13 python3.12 python3.11 python3; do \
	command -v $$p >/dev/null 2>&1 && $$p -c 'import sys; sys.exit(sys.version_info < (3, 11))' && { echo $$p; break; }; done)
VENV ?= .venv
BIN := $(VENV)/bin
EXTRAS ?= testbed,service,dev
DEMO_OUT ?= demo-out

.PHONY: venv demo test bench lint clean ui-deps

venv: $(VENV)/.installed

$(VENV)/.installed: pyproject.toml
	@test -n "$(PYTHON)" || { echo "zonecast needs Python >= 3.11 on PATH"; exit 1; }
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[$(EXTRAS)]'
	@# the stepping kernels compiled once into numba's cache (~12 s), not in every process
	$(BIN)/python -c "from zonecast.estimator.integrate import compile_kernels; compile_kernels()"
	@touch $@

demo: venv
	$(BIN)/zonecast demo --out $(DEMO_OUT)

# the suite on every core (pytest-xdist); each test keeps its own broker port, database
# schema and temporary folders
test: venv
	$(BIN)/python -m pytest -q -n auto

# every benchmark with its defaults; one that needs inputs (a campaign, a model file: argparse
# exits 2 and prints its usage) is named and skipped, any other failure stops the run
bench: venv
	@for b in benchmarks/bench_*.py; do echo "== $$b"; $(BIN)/python $$b; rc=$$?; \
	  if [ $$rc -eq 2 ]; then echo "   skipped: needs inputs (python $$b --help)"; \
	  elif [ $$rc -ne 0 ]; then exit $$rc; fi; done

# Debian's headless browser for tests/service/test_ui.py (the /ui page); the test skips,
# saying so, without them. Needs root (or run the apt-get line with sudo).
ui-deps:
	apt-get install -y chromium chromium-driver

lint: venv
	$(BIN)/ruff check estimator service testbed zonecast tests

clean:
	rm -rf $(VENV) $(DEMO_OUT) build *.egg-info
