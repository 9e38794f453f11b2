# Two commands for a newcomer: `make demo` and `make test`.
# Each creates .venv when missing and installs the project (editable) with what it needs.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed-stamp

.PHONY: demo stand test bench residuals nao contact walk walk-pulled guided arms install clean

install: $(STAMP)

$(STAMP): pyproject.toml
	@$(PYTHON) -c 'import sys; sys.exit(0 if sys.version_info >= (3, 10) else "error: Python >= 3.10 is required, found " + sys.version.split()[0])'
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e ".[test]"
	@touch $(STAMP)

demo: $(STAMP)
	$(PY) -m apps.push_and_comply $(ARGS)

stand: $(STAMP)
	$(PY) -m apps.stand $(ARGS)

test: $(STAMP)
	@command -v chromium >/dev/null 2>&1 || [ "$$(id -u)" != 0 ] || ! command -v apt-get >/dev/null 2>&1 || \
		{ echo "installing Debian's chromium for the replay browser test"; \
		  (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium) >/dev/null 2>&1 || true; }
	$(PY) -m pytest -q $(ARGS)

bench: $(STAMP)
	$(PY) -m apps.benchmark $(ARGS)

residuals: $(STAMP)
	$(PY) -m apps.residual_comparison $(ARGS)

nao: $(STAMP)
	$(PY) -m apps.nao_force_observer $(ARGS)

contact: $(STAMP)
	$(PY) -m apps.contact_localization $(ARGS)

walk: $(STAMP)
	$(PY) -m apps.nao_walk $(ARGS)

walk-pulled: $(STAMP)
	$(PY) -m apps.nao_walk_with_force $(ARGS)

guided: $(STAMP)
	$(PY) -m apps.nao_force_guided_walk $(ARGS)

arms: $(STAMP)
	$(PY) -m apps.nao_compliant_arms $(ARGS)

clean:
	rm -rf $(VENV) out .pytest_cache
