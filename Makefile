# EMML reproduction harness. `make demo` and `make test` work on a fresh machine with Python 3.11.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
TORCH_SPEC ?= torch==2.13.0
PROFILE ?= quick
BACKEND ?= local
# tcmalloc when present (never required): without it `emml` tunes glibc malloc in-process (docs/throughput.md)
TCMALLOC := $(firstword $(wildcard /usr/lib/x86_64-linux-gnu/libtcmalloc_minimal.so.4 /usr/lib/x86_64-linux-gnu/libtcmalloc.so.4))
EMML := $(if $(TCMALLOC),LD_PRELOAD=$(TCMALLOC) )$(VENV)/bin/emml

.PHONY: setup demo test test-slow lint bench bench-gpu ui table2 ablations transfer house3d reports list campaign campaign-status

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
	$(PY) -m pytest -q -n auto

# the learning checks too long for CI (tests marked slow: the end-to-end SGN test on learned detectors, ~8 min)
test-slow: setup
	$(PY) -m pytest -q -m slow

# ruff, then the import layers of pyproject.toml ([tool.importlinter]: nothing imports a layer above it)
lint: setup
	$(VENV)/bin/ruff check emml tests
	$(VENV)/bin/lint-imports

bench: setup
	$(EMML) bench env

# the prepared GPU check (issue 51): on a lent GPU machine, which has no .venv (its python3 holds torch), so no setup;
# a dry run here: make bench-gpu DEVICE=cpu RUNS=2 UPDATES=1 PROFILES=smoke
bench-gpu:
	scripts/gpu-check

# the committed run dirs into the store first (emml import-runs: once each; later calls only skip), then the browser;
# a run dir that cannot be imported is named and the browser opens all the same
ui: setup
	-MLFLOW_TRACKING_URI=sqlite:///$(CURDIR)/mlflow.db $(EMML) import-runs
	$(VENV)/bin/mlflow ui --backend-store-uri sqlite:///mlflow.db

# The paper's tables (reproduce/tableN.toml): every run under PROFILE, skipping finished ones, resuming the rest.
# BACKEND=slurm submits submitit jobs of PACK runs each, requeued at TIME_MIN until their runs finish
# (pip install -e ".[slurm]"; PARTITION, TIME_MIN, GPUS, PACK below; README "On a Slurm cluster").
PARTITION ?=
TIME_MIN ?= 1440
GPUS ?= 0
PACK ?= 1
# ONLY="difficulty=easy seed=0" trains a subset of a table's runs (emml run --only)
ONLY ?=
RUN_OPTS = --profile $(PROFILE) --backend $(BACKEND) $(if $(PARTITION),--partition $(PARTITION)) --time-min $(TIME_MIN) --gpus $(GPUS) --pack $(PACK) $(foreach o,$(ONLY),--only $(o))
TABLES := table2 table3 table4 table5

table2: setup
	$(EMML) run table2 $(RUN_OPTS)

ablations: setup
	$(EMML) run table3 $(RUN_OPTS)

# Table 4: SGN-only runs on the training instructions' words, then detectors for 'red' and 'pillar' appended
transfer: setup
	$(EMML) run table4 $(RUN_OPTS)

# Table 5: all 7 models in the House (Appendix C; emml/House-v0, our ViZDoom substitute for House3D), no aux
house3d: setup
	$(EMML) run table5 $(RUN_OPTS)
	$(EMML) visualize house --out reports

# An ordered, resumable list of table runs (reproduce/campaigns/CAMPAIGN.toml), trained from a git worktree of
# this commit (.campaign/<sha>) into this checkout's runs/, results/ and MLflow store; campaign-status shows it.
CAMPAIGN ?= reference

campaign: setup
	$(EMML) campaign $(CAMPAIGN)

campaign-status: setup
	$(EMML) campaign $(CAMPAIGN) --status

# every profile with results: reports/tableN-PROFILE.{md,tex}, -curves.{png,pdf}, the best Dual-Attention run's
# figures (when its run dir is here), the same for the experiments of reproduce/experiments/ with results, and
# reports/index.md linking them all
reports: setup
	$(EMML) reports

list: setup
	$(EMML) list --profile $(PROFILE)
