# r2sgen: `make demo` sets everything up and runs the whole pipeline on shipped data; `make test` runs the tests.
PYTHON ?= python3.11
VENV   ?= .venv
PY     := $(VENV)/bin/python
R2S    := $(VENV)/bin/r2s
STAMP  := $(VENV)/.installed

.PHONY: setup demo test bench corpus clean lint

setup: $(STAMP)

# Pinned dependencies (requirements.lock), then the project itself in editable mode.
$(STAMP): requirements.lock pyproject.toml
	@command -v $(PYTHON) >/dev/null 2>&1 || { echo "make setup: $(PYTHON) not found (set PYTHON=...)"; exit 2; }
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --disable-pip-version-check -r requirements.lock
	$(PY) -m pip install --quiet --disable-pip-version-check --no-deps -e .
	touch $(STAMP)

test: setup
	$(PY) -m pytest

lint: setup
	$(VENV)/bin/ruff check synth extractors pipeline bench tests

clean:
	rm -rf demo-out .pytest_cache .hypothesis
