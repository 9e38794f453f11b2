# Two commands for a newcomer: `make demo` and `make test`.
# Each creates .venv when missing and installs what the project needs into it (its
# dependencies and its metadata only: the code runs from this folder, see pyproject.toml).
# The interpreter decides the Drake release (pyproject.toml: drake>=1.51.1,<1.59): Python
# 3.12 and 3.13 get drake 1.58, Python 3.11 drake 1.51.1. `make PYTHON=python3.11 ...` picks
# it, once: later commands without PYTHON keep the environment's interpreter. Without PYTHON
# a new environment gets Python 3.12 where it is installed (today's Drake, and the main job's
# closed loop runs faster on it: BENCHMARKS.md), else python3. A pyenv interpreter
# (`pyenv versions`) is found even when no pyenv shell selected it.
# The environment; a second one beside it, e.g. VENV=.venv-py3.11, keeps both releases.
VENV ?= .venv
PYENV_VERSIONS = $${PYENV_ROOT:-$$HOME/.pyenv}/versions
ifeq ($(origin PYTHON),undefined)
PYTHON := $(if $(wildcard $(VENV)/bin/python),$(VENV)/bin/python,$(shell \
	{ python3.12 -c '' 2>/dev/null || ls -d "$(PYENV_VERSIONS)"/3.12.*/bin/python3.12 2>/dev/null | grep -q .; } \
	&& echo python3.12 || echo python3))
endif
PYTHON_BIN := $(shell $(PYTHON) -c 'import sys; print(sys.executable)' 2>/dev/null || \
	{ v=$$(echo '$(PYTHON)' | sed -n 's/^python\([0-9][0-9.]*\)$$/\1/p'); [ -n "$$v" ] && \
	  ls -d "$(PYENV_VERSIONS)"/$$v.*/bin/python$$v 2>/dev/null | sort -V | tail -n 1; })
PYTHON_VERSION := $(shell '$(PYTHON_BIN)' -c 'import sys; print("%d.%d" % sys.version_info[:2])' 2>/dev/null)
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed-python$(PYTHON_VERSION)
# Drake's SAP contact solver allocates and frees memory at every time step: with tcmalloc
# preloaded (Debian's libtcmalloc-minimal4) the simulations take less time per step
# (BENCHMARKS.md's closed-loop block says which allocator its run used: "Memory allocator of
# this run"). The apps use it when it is installed; `make install` installs it when run as
# root with apt-get. The tests run on the system allocator.
TCMALLOC = $$(ls /usr/lib/*-linux-gnu/libtcmalloc_minimal.so.4 /usr/lib64/libtcmalloc_minimal.so.4 2>/dev/null | head -n 1)
# The apps write their plots to files: matplotlib's file backend unless the caller chose one.
MPLBACKEND ?= Agg
export MPLBACKEND
# `make test`'s processes (pytest-xdist): every core by default, e.g. TEST_WORKERS=1.
TEST_WORKERS ?= auto
RUN = LD_PRELOAD="$(TCMALLOC)$${LD_PRELOAD:+ $$LD_PRELOAD}" $(PY)

.PHONY: sweep engine-scaling test-slow test-all docs hawley-settings paper-settings paper-speed robots scenarios demo demo-check contact residuals push-and-comply standing residual-comparison contact-localization model-refinement estimate-from-log base-state-from-log nao-force-observer nao-walk nao-walk-pulled nao-force-guided-walk nao-compliant-arms benchmark time-tests test install clean

install: $(STAMP)

$(STAMP): pyproject.toml
	@test -n "$(PYTHON_BIN)" || { echo "error: '$(PYTHON)' is not a Python interpreter here (make PYTHON=python3.X; pyenv versions)"; exit 1; }
	@'$(PYTHON_BIN)' -c 'import sys; sys.exit(0 if (3, 11) <= sys.version_info[:2] < (3, 14) else "error: Python 3.11 to 3.13 is required (pyproject.toml), found " + sys.version.split()[0] + ": run make PYTHON=python3.X")'
	@if [ -x $(PY) ] && [ "$$($(PY) -c 'import sys; print("%d.%d" % sys.version_info[:2])')" != "$(PYTHON_VERSION)" ]; then \
		echo "$(VENV) was made with another Python than $(PYTHON) ($(PYTHON_VERSION)): making it anew"; rm -rf $(VENV); fi
	@test -x $(PY) || '$(PYTHON_BIN)' -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet ".[test,cluster]"
	@echo "compiling the invariant EKF's steps, the floating-base kernels and the localizer's geometric queries (numba, once; cached beside their source)"
	@$(PY) -c 'from systems.estimation.base_state_estimator import load_compiled_filter_steps; load_compiled_filter_steps()'
	@$(PY) -c 'from systems.dynamics.floating_base_kernels import load_compiled_kernels; load_compiled_kernels()'
	@$(PY) -c 'from systems.residuals.geometry_intersection import load_compiled_queries; load_compiled_queries()'
	@ls /usr/lib/*-linux-gnu/libtcmalloc_minimal.so.4 >/dev/null 2>&1 || [ "$$(id -u)" != 0 ] || ! command -v apt-get >/dev/null 2>&1 || \
		{ echo "installing Debian's libtcmalloc-minimal4 (a faster memory allocator for the simulations)"; \
		  (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq libtcmalloc-minimal4) >/dev/null 2>&1 || true; }
	@$(PY) -c 'import importlib.metadata as m, sys; print("installed in $(VENV): Python", sys.version.split()[0], "with drake", m.version("drake"))'
	@touch $(STAMP)

test: $(STAMP)
	$(PY) -m ruff check .
	$(PY) -m ruff format --check .
	$(PY) -m pytest -q -n $(TEST_WORKERS) --dist loadfile -m "not slow" $(ARGS)

# The tests marked slow (pyproject.toml: long simulations, calibrations, full-length
# experiments): CI runs them after `make test`; `make test-all` runs both.
test-slow: $(STAMP)
	@command -v chromium >/dev/null 2>&1 || [ "$$(id -u)" != 0 ] || ! command -v apt-get >/dev/null 2>&1 || \
		{ echo "installing Debian's chromium for the replay browser test"; \
		  (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium) >/dev/null 2>&1 || true; }
	$(PY) -m pytest -q -n $(TEST_WORKERS) --dist loadfile -m slow $(ARGS)

test-all: test test-slow

# The main job (README): the push-and-comply experiment.
demo: push-and-comply

# A short main-job run (3 s, one push, realistic world with its calibration) that fails on
# any deprecation message Drake prints: CI runs it on each tested Drake release.
demo-check: $(STAMP)
	@echo "a short push-and-comply run on $$($(PY) -c 'import importlib.metadata as m; print("drake", m.version("drake"))')"
	@$(RUN) -m apps.push_and_comply --headless --out $(VENV)/demo-check \
		--scenario-text '{duration: 3.0, tare_duration: 0.8, push_start: 1.0, push_peak_time: 1.5, push_end: 2.5}' > $(VENV)/demo-check.log 2>&1; \
		status=$$?; cat $(VENV)/demo-check.log; [ $$status = 0 ] || exit $$status; \
		if grep -i "deprecat" $(VENV)/demo-check.log; then echo "error: the main job printed a deprecation message (above)"; exit 1; fi

# The short names the issues use: the contact study and the residual comparison.
contact: contact-localization
residuals: residual-comparison

# One target per experiment, named as its app (apps/<name>.py) and its diagram.
push-and-comply: $(STAMP)
	$(RUN) -m apps.push_and_comply $(ARGS)

standing: $(STAMP)
	$(RUN) -m apps.standing $(ARGS)

residual-comparison: $(STAMP)
	$(RUN) -m apps.residual_comparison $(ARGS)

contact-localization: $(STAMP)
	$(RUN) -m apps.contact_localization $(ARGS)

model-refinement: $(STAMP)
	$(RUN) -m apps.model_refinement $(ARGS)

# Offline: the estimators on a recorded log (ARGS="--robot FILE.yaml --log LOG").
estimate-from-log: $(STAMP)
	$(RUN) -m apps.estimate_from_log $(ARGS)

# The base-state estimate from a robot's own log against its truth (issue 32): the simulated
# walking test bed (writes results/base_state_from_log.json), or ARGS="--robot R --log LOG --truth CSV".
base-state-from-log: $(STAMP)
	$(RUN) -m apps.base_state_from_log $(if $(ARGS),$(ARGS),--results base_state_from_log)

nao-force-observer: $(STAMP)
	$(RUN) -m apps.nao_force_observer $(ARGS)

nao-walk: $(STAMP)
	$(RUN) -m apps.nao_walk $(ARGS)

nao-walk-pulled: $(STAMP)
	$(RUN) -m apps.nao_walk_pulled $(ARGS)

nao-force-guided-walk: $(STAMP)
	$(RUN) -m apps.nao_force_guided_walk $(ARGS)

nao-compliant-arms: $(STAMP)
	$(RUN) -m apps.nao_compliant_arms $(ARGS)

# The timings of BENCHMARKS.md: prints them and writes results/benchmark.json (then `make docs`).
benchmark: $(STAMP)
	$(RUN) -m apps.benchmark --results benchmark $(ARGS)

# make test's wall time on 2 workers (issue 33's floor), into results/test_suite.json: run it
# on an idle machine.
time-tests: $(STAMP)
	$(PY) -m apps.time_test_suite --results test_suite $(ARGS)

# Flacco et al. Sec. IV as published, then each of the project's changes (issue 31), and the
# realistic push-and-comply on several robots: both write results/*.json (about 10 and 20 min).
paper-settings: $(STAMP)
	$(RUN) -m apps.push_and_comply_study --study ablation $(ARGS)

robots: $(STAMP)
	$(RUN) -m apps.push_and_comply_study --study robots $(ARGS)

# Hawley et al.'s experiments 1-3 three ways, each writing its results file: the paper's
# setting (step loads, nominal stance), steps in the wider stance, the default (5 s ramps, wider stance).
hawley-settings: $(STAMP)
	$(RUN) -m apps.nao_force_observer --headless --no-replay --scenario apps/scenarios/hawley_paper.yaml --results nao_force_observer_paper $(ARGS)
	$(RUN) -m apps.nao_force_observer --headless --no-replay --scenario apps/scenarios/hawley_steps_wide.yaml --results nao_force_observer_steps_wide $(ARGS)
	$(RUN) -m apps.nao_force_observer --headless --no-replay --results nao_force_observer $(ARGS)

# The paper's speed claim (Sec. III): classical residual with an explicit C against the internal one.
paper-speed: $(STAMP)
	$(RUN) -m apps.paper_speed $(ARGS)

# The generated tables of README.md, docs/*.md and BENCHMARKS.md, from results/*.json, and the
# figures of the docs pages, drawn from them into docs/_generated/figures (not tracked); then
# the documentation site (docs/conf.py: the guides and the API reference built from the
# docstrings) into docs/_build/html (open docs/_build/html/index.html), with warnings as errors:
# -W --keep-going lists them all, -E reads every page again so that none is hidden by an
# earlier build (about 2 min on one core; tests/test_docs.py builds it the same way).
docs: $(STAMP)
	$(PY) -m apps.doc_tables
	$(PY) -m apps.doc_figures
	$(PY) -m sphinx -b html -E -W --keep-going -q docs docs/_build/html

# The contact study swept over robots, imperfection draws and noise levels (issue 35): a small
# grid here on Ray (about 20 min on 2 cores; writes out/sweep/ and results/sweep_small.json);
# ARGS="--cluster HOST:PORT" runs it on a Ray cluster, ARGS="--resume" goes on after a stop.
sweep: $(STAMP)
	$(RUN) -m apps.sweep --grid apps/scenarios/sweep_small.yaml --results sweep_small $(ARGS)

# How the studies scale: the same study on the pool and on Ray, the driver's cost, a model of
# N nodes (about 15 min; run it on an idle machine; writes results/engine_scaling.json).
engine-scaling: $(STAMP)
	$(RUN) -m apps.engine_scaling --results engine_scaling $(ARGS)

# The apps' default scenario files (apps/scenarios/*_default.yaml), written from the dataclasses.
scenarios: $(STAMP)
	$(PY) -m apps.write_scenarios

clean:
	rm -rf $(VENV) out .pytest_cache build *.egg-info
