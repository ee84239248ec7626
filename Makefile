# Every target bootstraps .venv (Python 3.12) and installs the project by itself.
SHELL := /bin/bash
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: install sysdeps test lint demo

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

install: $(STAMP) sysdeps

test: install
	$(PY) -m pytest -q tests

lint: install
	$(VENV)/bin/ruff check lerobot_predvla lerobot_policy_predvla tests benchmarks

demo: install
	$(VENV)/bin/predvla synthetic-demo
