# visnav: `make run` (set up + main job) and `make test` (set up + test suite).
# Everything is installed into .venv; nothing is downloaded at run time.

PYTHON ?= python3
VENV ?= .venv
# PyPI's default torch is a multi-GB CUDA build; this pin picks the CPU wheel on our machines.
TORCH_SPEC ?= torch==2.13.0
PY := $(VENV)/bin/python
STAMP := $(VENV)/.visnav-installed
SOURCES := setup.cfg pyproject.toml $(shell find src worlds config ros -type f -not -name '*.pyc' 2>/dev/null)

# ROS 2 environment: the venv is the ament prefix; keep DDS traffic on this machine.
export AMENT_PREFIX_PATH := $(abspath $(VENV))
export ROS_AUTOMATIC_DISCOVERY_RANGE ?= LOCALHOST
export MUJOCO_GL ?= egl

.PHONY: run test test-slow setup system-deps lint bench demo clean sweep

# the main job: validate the env -> train 50k steps -> evaluate -> diagnose -> report (runs/)
run: setup
	$(VENV)/bin/visnav-pipeline $(ARGS)

# seeds 1-5 of the defaults (or a grid) on Ray Tune -> runs/sweep_<date>_<time>/Sweep.md
sweep: setup
	$(VENV)/bin/visnav-sweep $(ARGS)

# the policy node drives a realtime sim through one episode at wall-clock pace: the servo
# baseline, or a trained run with `make demo ARGS='--model runs/NAME'`; `ARGS=--live` serves it
# to Foxglove at ws://localhost:8765 (nav-sim-demo: the sim alone, a scripted lockstep episode)
demo: setup
	$(VENV)/bin/visnav-demo $(ARGS)

# CI runs this: lint first (ruff: style, quotes, pep257 docstrings), then the tests
test: lint
	$(PY) -m pytest -q

test-slow: setup
	$(PY) -m pytest -q -s -m slow

bench: setup
	$(PY) benchmarks/bench_sim.py
	$(PY) benchmarks/bench_env.py
	$(PY) benchmarks/bench_live.py
	$(PY) benchmarks/bench_learner.py
	$(PY) benchmarks/bench_policy.py
	$(PY) benchmarks/bench_envs.py

lint: setup
	$(VENV)/bin/ruff check src test benchmarks tools

setup: system-deps $(STAMP)

# MuJoCo's offscreen rendering needs EGL and Mesa (Debian: libegl1 libgl1-mesa-dri).
system-deps:
	@if ! ldconfig -p | grep -q 'libEGL.so.1'; then \
	  if [ "$$(id -u)" = 0 ]; then \
	    apt-get update -qq && apt-get install -y -qq libegl1 libgl1-mesa-dri; \
	  else \
	    echo 'missing EGL: run  sudo apt-get install libegl1 libgl1-mesa-dri'; exit 1; \
	  fi; \
	fi

$(STAMP): $(SOURCES)
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q '$(TORCH_SPEC)'
	$(PY) -m pip install -q '.[test]'
	touch $@

clean:
	rm -rf $(VENV) build src/*.egg-info
