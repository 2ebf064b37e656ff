# Every target creates the virtual environment itself (`.venv`) on first use.
PYTHON ?= python3.11
# Processes of `make benchmark` at once: training runs and evaluations (default: every CPU).
JOBS ?= $(shell nproc 2>/dev/null || echo 1)
VENV   ?= .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
OUT    ?= reproductions

.PHONY: help install demo test test-slow lint format reproduce bench benchmark clean

help:
	@echo "make demo       the main job: train a shared policy, evaluate it against every"
	@echo "                baseline of its task, write runs/demo/ (report, plots, GIFs)"
	@echo "make test       create .venv if missing, install, run ruff, mypy, codespell and pytest"
	@echo "make test-slow  the same, plus the slow tests (full training runs)"
	@echo "make lint       ruff (lint, format check), mypy (types) and codespell, as CI runs them"
	@echo "make reproduce  regenerate the paper figures (PNG + JSON + GIF) into $(OUT)/"
	@echo "make bench      print the physics throughput table"
	@echo "make benchmark  the results table: train every entry of configs/benchmark/results.yaml"
	@echo "                (3 seeds, JOBS=$(JOBS) processes at once), evaluate against the baselines, write"
	@echo "                runs/benchmark/results.{json,md,png} with 95 % bootstrap CIs (slow;"
	@echo "                rerun to continue after Ctrl-C)"
	@echo "make format     apply ruff format and autofixes"

$(BIN)/python:
	$(PYTHON) -m venv $(VENV) || python3 -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

$(STAMP): $(BIN)/python pyproject.toml setup.py constraints.txt
	$(BIN)/python -m pip install --quiet -c constraints.txt -e ".[dev,distributed,fast,benchmarl]"
	@touch $(STAMP)

install: $(STAMP)

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	$(BIN)/mypy
	$(BIN)/codespell

format: $(STAMP)
	$(BIN)/ruff format .
	$(BIN)/ruff check --fix .

test: lint
	$(BIN)/python -m pytest $(PYTEST_ARGS)

test-slow: lint
	$(BIN)/python -m pytest --runslow $(PYTEST_ARGS)

demo: $(STAMP)
	$(BIN)/swarm-demo --out runs/demo --overwrite

reproduce: $(STAMP)
	$(BIN)/swarm-reproduce --out $(OUT) --overwrite

bench: $(STAMP)
	$(BIN)/python benchmarks/physics.py
	$(BIN)/python benchmarks/envs.py

benchmark: $(STAMP)
	$(BIN)/swarm-benchmark --jobs $(JOBS)

clean:
	rm -rf $(VENV) .pytest_cache .ruff_cache .mypy_cache build swarm_envs/envs/cores/native/lib
