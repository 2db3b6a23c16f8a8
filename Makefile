# The two commands of the quick start: `make test` and `make sim`.
# Each creates .venv from pyproject.toml when it is missing or older than pyproject.toml.
PY ?= python3.11
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

export NUMBA_CACHE_DIR ?= $(CURDIR)/.cache/numba
export MPLBACKEND := Agg

.PHONY: test lint typecheck pytest sim hil bench results faults soak e2e docs venv clean

venv: $(STAMP)

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PY) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[dev]'
	touch $(STAMP)

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .

typecheck: $(STAMP)
	$(BIN)/mypy

# Every test on both cores (pytest-xdist), then the lockstep test alone: it makes its
# own load (a busy loop on both cores) and asserts that the same seed gives the same
# survey under it, which is what it is for, not how long it takes beside other tests.
LOCKSTEP := tests/integration/test_lockstep.py
pytest: $(STAMP)
	$(BIN)/pytest -q -n 2 --dist worksteal --durations=15 --ignore=$(LOCKSTEP)
	$(BIN)/pytest -q --durations=1 $(LOCKSTEP)

test: lint typecheck pytest

sim: $(STAMP)
	$(BIN)/phenorover sim

# The same survey with every device on its real wire (deploy/hil.toml): gnss, base and
# scanner run their hardware backends against simulated devices speaking NMEA over
# TCP, ROS 2 over rmw_zenoh and CAN over SLCAN.
hil: $(STAMP)
	$(BIN)/phenorover sim --manifest deploy/hil.toml

bench: $(STAMP)
	$(BIN)/python -m pip install --quiet -e '.[bench]' || echo "open3d not installable here: Embree comparison skipped"
	$(BIN)/python -c "import open3d" 2>/dev/null || echo "open3d does not load (Debian: apt-get install libusb-1.0-0): Embree comparison skipped"
	$(BIN)/python tests/bench/run_all.py

# docs/results.md from the benchmarks' JSON (docs/bench/*.json, written by `make bench`):
# a table per benchmark with the error models beside it; a missing JSON is said to be.
# Runs no benchmark.
results: $(STAMP)
	$(BIN)/python -m phenorover.eval.render_results

# The reference tables in docs/ (every option of the manifest, the field, the robot
# description and each service table; mission.db's columns) from the code: the
# options' attribute docstrings, defaults and bounds, the schema's comments. A doc that
# differs fails tests/docs/test_refdocs.py.
docs: $(STAMP)
	$(BIN)/python -m phenorover.refdocs

# The fault campaign: each service killed and each injected fault during a survey of
# the tiny field, judged by the simulator's truth; writes docs/bench/faults.json and
# the table in docs/faults.md. About half an hour on two cores.
faults: $(STAMP)
	$(BIN)/python tests/bench/fault_campaign.py

# Ten whole `phenorover sim --field F` runs of SPL and of two fields of our own, in a
# row; writes docs/bench/soak.json and docs/soak.md after every run. Three to four
# hours on two cores: `python tests/bench/soak.py --resume` continues a stopped soak.
soak: $(STAMP)
	$(BIN)/python tests/bench/soak.py

# The dashboard in a real browser: Debian's chromium (apt-get install chromium) opens
# the served web viewer during a short simulated survey; about two minutes.
e2e: $(STAMP)
	$(BIN)/python -m pip install --quiet -e '.[e2e]'
	PHENOROVER_E2E=1 $(BIN)/pytest -q tests/e2e

clean:
	rm -rf $(VENV) .cache .mypy_cache .ruff_cache runs
