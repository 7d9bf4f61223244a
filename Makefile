# Two entry points (see README): `make demo` (main job) and `make test` (test suite).
# Both create the virtual environment from pyproject.toml on first use.
PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
export OPENBLAS_NUM_THREADS ?= 1
export OMP_WAIT_POLICY ?= PASSIVE

.PHONY: install demo test lint

install: $(VENV)/.installed

$(VENV)/.installed: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --upgrade pip
	# torch first and pinned: the CPU wheel the machines hold (a bare `torch` would pull a CUDA build)
	$(PY) -m pip install "torch==2.13.0"
	$(PY) -m pip install -e ".[dev]"
	touch $@

# main job on the small embedded default: simulate a tiny dataset (sim=tiny, 5 stresses; skipped when
# present), train the 5-fold surrogate, write its report; then the dataset's flow curve
demo: install
	$(PY) train.py debug=tiny output_root=outputs/demo
	$(PY) -m rheograph.flowcurve data/tiny --out outputs/demo/flow_curve

test: install
	$(PY) -m pytest -q

lint: install
	$(VENV)/bin/ruff check src tests bench *.py
	$(VENV)/bin/ruff format --check src tests bench *.py
