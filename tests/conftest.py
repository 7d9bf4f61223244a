import os

# as simulate.py: single-threaded linear algebra (CHOLMOD starts OpenMP threads unless OMP_THREAD_LIMIT is
# set before libgomp loads: 1.6x the CPU time of a simulation on a busy 2-core machine)
os.environ.setdefault("OMP_THREAD_LIMIT", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

from pathlib import Path  # noqa: E402

import pytest  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="session")
def tiny_files(tmp_path_factory):
    """Three tiny simulated state points (N = 64, phi = 0.72, sigma = 0.5, 5, 50), ~10 snapshots each."""
    from rheograph.runs.runner import run_state_point
    from rheograph.sim.params import SimParams

    directory = tmp_path_factory.mktemp("tiny")
    files = []
    for stress in (0.5, 5.0, 50.0):
        params = SimParams(
            n_particles=64,
            phi=0.72,
            stress=stress,
            strain=0.3,
            snapshot_interval=0.025,
            steady_state_strain=0.05,
            disp_max=2e-3,
            integrator="implicit",
        )
        path = directory / f"s{stress:g}.h5"
        run_state_point(params, path, progress=False)
        files.append(str(path))
    return files


def load_bench_script(name: str):
    """A module of the bench package: ``load_bench_script("vs_lfdem")`` is ``bench.vs_lfdem``."""
    import importlib

    return importlib.import_module(f"bench.{name}")


def tiny_training_overrides(tiny_files, tmp_path) -> list[str]:
    """``train.py`` overrides that train on the tiny runs (not the paper-scale default's phi / N), with a
    cache of their own and snapshots from strain 0.05 on."""
    return [
        f"data.files={Path(tiny_files[0]).parent / '*.h5'}",
        f"data.cache_dir={tmp_path / 'cache'}",
        "data.phi=null",
        "data.n_particles=null",
        "data.num_folds=3",
        "graph.min_strain=0.05",
    ]


def sheared_frictional_problem(n_particles: int = 100, size_ratio: float = 1.4, steps: int = 300):
    """A dense frictional state (phi = 0.78, sigma/sigma0 = 20, implicit springs, 300 steps: contacts
    sticking and sliding, lubricated gaps) and its linear problem at that state, without changing it:
    (simulation, LinearProblem, dense resistance matrix (3N, 3N))."""
    from rheograph.sim import SimParams, Simulation
    from rheograph.sim.assembly import dense_from_upper_csc
    from rheograph.sim.integrator import linear_problem

    params = SimParams(
        n_particles=n_particles,
        phi=0.78,
        stress=20.0,
        size_ratio=size_ratio,
        integrator="implicit",
        disp_max=2e-3,
    )
    sim = Simulation(params)
    for _ in range(steps):
        sim.step()
    s, p = sim.state, params
    lp = linear_problem(
        s.positions, s.radii, s.pair_i, s.pair_j, s.lx, s.ly, s.le_offset, s.stretch.copy(),
        s.contact_state.copy(), p.kn, p.kt, p.mu, p.critical_load, p.lub_max_gap, p.delta, s.dt_assumed,
        sim.indptr, sim.pair_slot, sim.diag_slot, sim.indices.shape[0],
    )  # fmt: skip
    return sim, lp, dense_from_upper_csc(lp.data, sim.indices, sim.indptr, 3 * n_particles)


def train_tiny_fold(tiny_files, tmp_path, *overrides):
    """Fold 0 of a 2-epoch ``train.py`` run on the tiny runs with ``overrides``, into tmp_path/run (no
    logger, no report); returns the run directory."""
    from hydra import compose, initialize_config_dir

    from rheograph.learn.train import train_folds

    with initialize_config_dir(config_dir=str(ROOT / "conf"), version_base="1.3"):
        cfg = compose(
            "train",
            overrides=[
                *overrides,
                *tiny_training_overrides(tiny_files, tmp_path),
                "trainer.max_epochs=2",
                "trainer.enable_progress_bar=false",
                "~logger",
                "report=false",
                "fold=0",
            ],
        )
    train_folds(cfg, tmp_path / "run")
    return tmp_path / "run"


def resgcn(edge_in: int = 6, global_in: int = 0, **options):
    """``model.net`` as training completes it: the ResGCN partial with its input sizes filled in."""
    from functools import partial

    from rheograph.learn.model import ResGCN

    return partial(ResGCN, node_in=2, edge_in=edge_in, global_in=global_in, **options)
