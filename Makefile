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

# main job on the small embedded default: simulate a tiny stress grid, then report its flow curve
demo: install
	$(PY) simulate.py -m sim=tiny sim.stress=0.5,5,50 output_root=outputs/demo progress=false
	$(PY) -m rheograph.flowcurve outputs/demo/multirun --out outputs/demo/report

test: install
	$(PY) -m pytest -q

lint: install
	$(VENV)/bin/ruff check src tests bench simulate.py
	$(VENV)/bin/ruff format --check src tests bench simulate.py
