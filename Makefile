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

.PHONY: setup demo test test-slow lint docs mutate bench bench-gpu ui table2 ablations transfer house3d reports list campaign campaign-status

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

# the docs site (mkdocs.yml, docs/; MkDocs with the Material theme, in the dev extra) into site/: the CLI and config
# references generated first (docs/reference/, not committed), then built strictly: a broken link or anchor, or a page
# left out of the nav, fails it (tests/test_docs.py builds it the same way). `mkdocs serve` to browse it.
docs: setup
	$(PY) scripts/docs_reference.py docs/reference
	$(VENV)/bin/mkdocs build --strict

# Mutation testing (issue 66; docs/testing.md): mutmut over the modules that decide numbers, each against the tests
# that read it, then the score per module. Not in CI: 24 min on 2 idle cores for all of them (docs/testing.md), hours
# beside a training.
# Each module is mutated in its own copy of the checkout (scratch/mutate/<module>/: mutmut rewrites the files it
# mutates; the checkout is never touched), at nice 10. `make mutate MUTATE=rl/ppo` runs one; the survivors are then
# listed by `cd scratch/mutate/rl-ppo && ../../../.venv/bin/mutmut results` (`mutmut show NAME`: the diff).
MUTATE ?= experiments/claims/evidence experiments/claims/kinds report/claims report/chance report/aggregate report/efficiency rl/ppo rl/rollout envs/doom
# the claims' rules (emml/experiments/claims/) against their own tests (hand-worked tables, milliseconds each) and the
# paper's table; report/claims against those and the claims page's, chance's and efficiency's tests (fixtures of
# results rows: ~45 s a survivor beside a training); report/chance against its own and the paper's table
MUT_TESTS_RULES = $(wildcard tests/experiments/claims/test_*.py) tests/report/test_claims_on_paper.py
MUT_TESTS_CLAIMS = $(MUT_TESTS_RULES) tests/report/test_claims.py tests/report/test_claims_gather.py tests/report/test_claims_page.py tests/report/test_chance.py tests/report/test_efficiency.py
MUT_TESTS_experiments/claims/evidence = $(MUT_TESTS_RULES)
MUT_TESTS_experiments/claims/kinds = $(MUT_TESTS_RULES)
MUT_TESTS_report/claims = $(MUT_TESTS_CLAIMS)
MUT_TESTS_report/chance = tests/report/test_chance.py tests/report/test_claims_on_paper.py
MUT_TESTS_report/aggregate = tests/report/test_aggregate.py tests/report/test_aggregate_compare.py tests/report/test_aggregate_interval.py tests/report/test_bootstrap_at_once.py $(addprefix tests/report/test_tables.py::,test_the_aggregate_under_the_table test_the_aggregate_compares_like_with_like_issue_49)
MUT_TESTS_report/efficiency = tests/report/test_efficiency.py
MUT_TESTS_rl/ppo = tests/rl/test_ppo_losses.py tests/rl/test_advantage_normalisation.py tests/rl/test_ppo_by_hand.py tests/rl/test_gae.py tests/rl/test_rollout_buffer.py
MUT_TESTS_rl/rollout = tests/rl/test_gae.py tests/rl/test_rollout_buffer.py tests/rl/test_rollout_split_insert.py tests/rl/test_ppo_losses.py tests/rl/test_ppo_by_hand.py
MUT_TESTS_envs/doom = tests/envs/test_reach.py
# doom.py: its reward and success only (the engine's setup, spaces and labels are other tests' business)
MUT_NAMES_envs/doom = 'emml.envs.doom.x*DoomEnv*step__mutmut_*' 'emml.envs.doom.x*DoomEnv*_reached__mutmut_*' 'emml.envs.doom.x*DoomEnv*_target_distance__mutmut_*' 'emml.envs.doom.x*DoomEnv*_distances__mutmut_*'
# conftest.py builds an MLflow store per session (seconds per mutant): left out unless a module's tests need its
# fixtures; torch.compile cannot trace mutmut's trampolines (the traceability test, not a number)
MUT_CONFTEST =
MUT_DESELECT = --deselect tests/rl/test_ppo_losses.py::test_ppo_losses_read_nothing_back_from_the_device

mutate: $(addprefix mutate/,$(MUTATE))
	@echo "mutation score (killed or timed out, of the mutants run):"; cat $(foreach m,$(MUTATE),scratch/mutate/$(subst /,-,$(m))/score.txt)

mutate/%: setup
	@dir=scratch/mutate/$(subst /,-,$*); rm -rf $$dir; mkdir -p $$dir; cp -r emml tests reproduce pyproject.toml $$dir/; \
	{ echo "[mutmut]"; echo "source_paths = emml"; echo "only_mutate = emml/$*.py"; echo "also_copy = reproduce"; \
	  echo "process_isolation = forkserver"; echo "timeout_constant = 30"; echo "pytest_add_cli_args_test_selection ="; \
	  for t in $(MUT_TESTS_$*); do echo "    $$t"; done; echo "pytest_add_cli_args ="; \
	  for a in -p no:cacheprovider -p tests.mutmut_order $(if $(filter $*,$(MUT_CONFTEST)),,--noconftest) $(MUT_DESELECT); do echo "    $$a"; done; \
	} > $$dir/setup.cfg; \
	echo "mutmut on emml/$*.py ($$dir/mutmut.log)…"; \
	cd $$dir && { nice -n 10 $(CURDIR)/$(VENV)/bin/mutmut run $(MUT_NAMES_$*) > mutmut.log 2>&1 || { tail -c 3000 mutmut.log; exit 1; }; } && \
	$(CURDIR)/$(VENV)/bin/mutmut results --all true > results.txt && \
	awk -F': ' -v m=emml/$*.py '{ n[$$2]++ } END { run = NR - n["not checked"] - n["skipped"]; ok = n["killed"] + n["timeout"]; \
	  printf "  %s: %.1f%% (%d killed, %d timed out of %d run; %d survived, %d without a test)\n", m, run ? 100 * ok / run : 0, \
	  n["killed"], n["timeout"], run, n["survived"], n["no tests"] }' results.txt | tee score.txt

bench: setup
	$(EMML) bench env

# the prepared GPU check (issue 51): on a lent GPU machine, which has no .venv (its python3 holds torch), so no setup;
# a dry run here: make bench-gpu DEVICE=cpu RUNS=2 UPDATES=1 PROFILES=smoke
bench-gpu:
	scripts/gpu-check

# the committed run dirs into the store first (emml import-runs: once each; later calls only skip), then the browser;
# a run dir that cannot be imported is named and the browser opens all the same. One web worker and no job runner
# (MLflow's GenAI jobs, unused here): 2 processes instead of 15, up in 18 s instead of 39 s beside a training
ui: setup
	-MLFLOW_TRACKING_URI=sqlite:///$(CURDIR)/mlflow.db $(EMML) import-runs
	MLFLOW_SERVER_ENABLE_JOB_EXECUTION=false $(VENV)/bin/mlflow ui --backend-store-uri sqlite:///mlflow.db --workers 1

# The paper's tables (reproduce/tableN.toml): every run under PROFILE, skipping finished ones, resuming the rest.
# BACKEND=slurm submits submitit jobs of PACK runs each, requeued at TIME_MIN until their runs finish
# (pip install -e ".[slurm]"; PARTITION, TIME_MIN, GPUS, PACK below; docs/slurm.md).
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
	$(EMML) campaign run $(CAMPAIGN)

campaign-status: setup
	$(EMML) campaign status $(CAMPAIGN)

# every profile with results: reports/tableN-PROFILE.{md,tex}, -curves.{png,pdf}, the best Dual-Attention run's
# figures (when its run dir is here), the same for the experiments of reproduce/experiments/ with results, and
# reports/index.md linking them all
reports: setup
	$(EMML) reports

list: setup
	$(EMML) list --profile $(PROFILE)
