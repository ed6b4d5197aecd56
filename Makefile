# EMML reproduction harness. `make demo` and `make test` work on a fresh machine with Python 3.11.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
TORCH_SPEC ?= torch==2.13.0
PROFILE ?= quick
BACKEND ?= local
# tcmalloc roughly doubles CPU training throughput here (notes/cpu-training.md); used when present, never required
TCMALLOC := $(firstword $(wildcard /usr/lib/x86_64-linux-gnu/libtcmalloc_minimal.so.4 /usr/lib/x86_64-linux-gnu/libtcmalloc.so.4))
EMML := $(if $(TCMALLOC),LD_PRELOAD=$(TCMALLOC) )$(VENV)/bin/emml

.PHONY: setup demo test lint bench ui

setup: $(VENV)/.installed

# torch first (the CPU wheel here; TORCH_SPEC for a CUDA build), so the package's torch>=2.4 range installs nothing more
$(VENV)/.installed: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q "$(TORCH_SPEC)"
	$(PY) -m pip install -q -e ".[dev]"
	touch $@

demo: setup
	$(EMML) demo

test: setup
	$(PY) -m pytest -q

lint: setup
	$(VENV)/bin/ruff check emml tests

bench: setup
	$(EMML) bench env

ui: setup
	$(VENV)/bin/mlflow ui --backend-store-uri sqlite:///mlflow.db
