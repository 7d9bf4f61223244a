# Two entry points (see README): `make demo` (main job) and `make test` (test suite).
# Both create the virtual environment from pyproject.toml on first use.
PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
export OPENBLAS_NUM_THREADS ?= 1
export OMP_WAIT_POLICY ?= PASSIVE
# System packages for the CHOLMOD solver backend (rheograph.sim.solver): SuiteSparse headers for
# scikit-sparse, and OpenBLAS as the system BLAS (the supernodal factorisation is 2.1x faster with it
# than with Debian's reference BLAS at N = 2000: 5.8 against 12.4 ms, docs/validation/speed.md).
SYSTEM_PACKAGES := libsuitesparse-dev libopenblas0-serial
SUDO := $(if $(filter 0,$(shell id -u)),,sudo)

.PHONY: install system-packages demo test test-slow lint docs cards bench bench-render bench-quick clean-numba

install: $(VENV)/.installed

# without apt-get or sudo rights the install goes on without them (and without the cholmod extra)
system-packages:
	@dpkg -s $(SYSTEM_PACKAGES) >/dev/null 2>&1 || { \
	  $(SUDO) env DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends $(SYSTEM_PACKAGES) || \
	  { $(SUDO) apt-get update && \
	    $(SUDO) env DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends $(SYSTEM_PACKAGES); }; } || \
	  echo "warning: could not install $(SYSTEM_PACKAGES) (without SuiteSparse the sparse solver is pip's qdldl)"

# torch first and pinned (a bare `torch` would pull a CUDA build of several GB): the CPU wheel where
# pip's configuration provides it; elsewhere TORCH_INDEX=https://download.pytorch.org/whl/cpu
TORCH_INDEX ?=
$(VENV)/.installed: pyproject.toml | system-packages
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --upgrade pip
	$(PY) -m pip install "torch==2.13.0" $(if $(TORCH_INDEX),--index-url $(TORCH_INDEX))
	if [ -e /usr/include/suitesparse/cholmod.h ]; then extras=dev,cholmod; else extras=dev; fi; \
	$(PY) -m pip install -e ".[$$extras]"
	touch $@

# main job: a short simulation (N = 400, phi = 0.76, sigma/sigma0 = 10, 0.3 strain; resumed, i.e. skipped,
# when already done), then the surrogate trained on the committed phi = 0.76 part of the paper-scale set
# with whole trajectories held out (its R² and report path printed), then the set's flow curves
demo: install
	$(PY) simulate.py sim.phi=0.76 sim.stress=10 sim.strain=0.3 sim.steady_state_strain=0.1 \
	    sim.integrator=implicit sim.disp_max=2e-3 \
	    output_root=outputs/demo/simulate
	$(PY) train.py experiment=demo
	$(PY) -m rheograph.analysis.flow_curves data/paper --out outputs/demo/flow_curve

test: install
	$(PY) -m pytest -q

# the long tests (N = 400 runs against LF_DEM's series, dense high-stress runs): CI runs them after `test`
test-slow: install
	$(PY) -m pytest -q -m slow

# the published tables: every marked section of the docs pages against its JSON record under
# docs/results/bench/ (fails naming the sections that differ); bench-render rewrites them from the records
bench: install
	$(PY) -m bench.render --check

bench-render: install
	$(PY) -m bench.render

# a few cheap benchmarks rerun at small size into a temporary folder (a minute): do they still run and
# write records of the right schema?  The full benchmarks take hours: see docs/validation/index.md
bench-quick: install
	$(PY) -m bench.quick

# the documentation (mkdocs + mkdocstrings; reference pages generated from the code), into site/: warnings
# and broken links fail the build
docs: $(VENV)/.docs-installed
	$(VENV)/bin/mkdocs build --strict

$(VENV)/.docs-installed: $(VENV)/.installed
	$(PY) -m pip install -e ".[docs]"
	touch $@

lint: install
	$(VENV)/bin/ruff check src tests bench *.py
	$(VENV)/bin/ruff format --check src tests bench *.py

# the dataset cards of the committed sets (tables and figures from the trajectory files; each quotes the
# simulate commands that regenerate its runs), and the records of the figures' numbers (python -m bench.render)
cards: install
	$(PY) -m rheograph.analysis.dataset_card data/paper --out docs \
	    --record docs/results/bench/figures/dataset_paper.json
	$(PY) -m rheograph.analysis.dataset_card data/flow_curves_3d --out docs/datasets/flow_curves_3d \
	    --record docs/results/bench/figures/dataset_flow_curves_3d.json \
	    --title "Dataset card: the 3D flow-curve set (in progress)" \
	    --command "python simulate.py -m campaign=flow_curves_3d"
	$(PY) -m rheograph.analysis.dataset_card data/near_jamming_3d --out docs/datasets/near_jamming_3d \
	    --record docs/results/bench/figures/dataset_near_jamming_3d.json \
	    --title "Dataset card: the 3D plateau near jamming, with elastic unloading (in progress)" \
	    --command "python simulate.py -m campaign=near_jamming_3d"
	$(PY) -m rheograph.analysis.dataset_card data/polydisperse_flow_curves_3d \
	    --out docs/datasets/polydisperse_flow_curves_3d \
	    --record docs/results/bench/figures/dataset_polydisperse_flow_curves_3d.json \
	    --title "Dataset card: 3D flow curves of polydisperse spheres" \
	    --command "python simulate.py -m campaign=polydisperse_flow_curves_3d"
	$(PY) -m rheograph.analysis.dataset_card data/jamming --out docs/datasets/jamming \
	    --record docs/results/bench/figures/dataset_jamming.json \
	    --title "Dataset card: runs near jamming" \
	    --command "python simulate.py -m campaign=jamming_frictionless hydra.launcher.n_jobs=1   # mu = 0" \
	    --command "python simulate.py -m campaign=jamming_frictionless hydra.launcher.n_jobs=1 sim.n_particles=2000 sim.strain=3 sim.phi=0.82,0.83,0.835 sim.seed=1,2" \
	    --command "python simulate.py -m campaign=jamming_frictionless hydra.launcher.n_jobs=1 sim.n_particles=2000 sim.strain=3 sim.phi=0.84 sim.relax_tolerance=3e-3 sim.seed=1,2" \
	    --command "python simulate.py -m campaign=jamming_frictionless hydra.launcher.n_jobs=1 sim.n_particles=2000 sim.strain=3 sim.phi=0.845 sim.relax_tolerance=2e-2 sim.seed=1,2" \
	    --command "python simulate.py -m campaign=jamming_frictional hydra.launcher.n_jobs=1   # phi 0.79" \
	    --command "python simulate.py -m campaign=jamming_frictional hydra.launcher.n_jobs=1 sim.stress=200 sim.phi=0.785,0.795 sim.seed=1,2,3,4,5,6" \
	    --command "python simulate.py -m campaign=jamming_frictional hydra.launcher.n_jobs=1 sim.stress=200 sim.phi=0.79 sim.seed=4,5,6" \
	    --command "python simulate.py -m campaign=jamming_frictional hydra.launcher.n_jobs=1 sim.stress=200 sim.phi=0.7875 sim.seed=1,2,3" \
	    --command "python simulate.py -m campaign=jamming_frictional hydra.launcher.n_jobs=1 sim.stress=200 sim.n_particles=2000 sim.phi=0.81 sim.seed=1" \
	    --command "python simulate.py -m campaign=jamming_frictional hydra.launcher.n_jobs=1 sim.stress=200 sim.n_particles=2000 sim.phi=0.78,0.79 sim.seed=1,2" \
	    --command "python simulate.py -m campaign=jamming_frictional hydra.launcher.n_jobs=1 sim.stress=200 sim.n_particles=2000 sim.phi=0.795 sim.seed=1"
	$(PY) -m rheograph.analysis.dataset_card data/large_n --out docs/datasets/large_n \
	    --record docs/results/bench/figures/dataset_large_n.json \
	    --title "Dataset card: large systems" \
	    --command "python simulate.py -m campaign=large_n hydra.launcher.n_jobs=1 sim.n_particles=400,2000   # phi 0.76" \
	    --command "python simulate.py -m campaign=large_n hydra.launcher.n_jobs=1   # N = 8000" \
	    --command "python simulate.py -m campaign=large_n hydra.launcher.n_jobs=1 sim.n_particles=20000" \
	    --command "python simulate.py -m campaign=large_n_jamming hydra.launcher.n_jobs=1   # phi 0.80, N = 8000" \
	    --command "python simulate.py -m campaign=large_n_jamming hydra.launcher.n_jobs=1 sim.stress=20 sim.seed=2" \
	    --command "python simulate.py -m campaign=large_n_jamming hydra.launcher.n_jobs=1 sim.n_particles=20000 sim.stress=20"

# numba's compiled kernels (beside the sources): its cache misses a change in a called kernel's file, so
# clear it after editing or pulling the simulator's sources in an editable install (docs/faults.md)
clean-numba:
	find src -name '*.nbi' -delete -o -name '*.nbc' -delete
