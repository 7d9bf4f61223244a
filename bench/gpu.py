"""Training and prediction on a GPU against the CPU, in one run: JSON results, a table for the docs.

    PYTHONPATH=src python -m bench.gpu --device cuda --out gpu.json        # about 6 min on one GPU
    PYTHONPATH=src python -m bench.gpu --device cpu --quick --out q.json   # a smoke run of every part
    PYTHONPATH=src python -m bench.gpu_report gpu.json                    # the markdown table

All on the committed φ = 0.76, N = 400 set with ``experiment=demo`` settings (width 32, 60 epochs, five
folds of held-out trajectories); the graph cache is built first, into a fresh directory, and timed on
its own. Parts (``--parts``, default all):

* ``a``: seconds per training epoch of fold 0 (median of ``--repeats`` epochs after one warm-up epoch,
  validation excluded) with PyG's per-batch loader (``data.device_resident=false``) and with the graph
  sets kept on the device, at batch 32 and 128.
* ``b``: the five folds trained for 60 epochs one after the other in this process, with the demo's batch
  32 / learning rate 5e-3 and with ``experiment=demo_gpu``'s 128 / 1e-2: each fold's wall time
  (training, test, baselines) and held-out R² of log η_r, log Π and Z_μ.
* ``c``: ``train.py experiment=demo_gpu`` end to end on a GPU (``experiment=demo fold_workers=1`` on the
  CPU): a fresh process, imports, five folds, report, the graph cache already built.
* ``d``: prediction with the shipped models: 1000 snapshots of N = 400 (the committed snapshots
  repeated), one of N = 2000 (data/paper) and one of N = 20 000 (data/large_n, the N = 2000 model): the
  physics inputs (graphs with their one resistance solve, spring pressure, contact counts; on the CPU,
  ``--workers`` processes) and the networks' forward passes (five fold models) timed apart, each the
  median of ``--repeats`` after a warm-up.
* ``f``: where dense batches pay: one resistance problem's solve (factorisation and the two right-hand
  sides) by the sparse Cholesky on one CPU core against the dense batched Cholesky on ``--device`` (the
  time of a batch divided by its problems), at 2D N = 400 to 4000 and 3D N = 500 to 2000 (on a CPU
  up to 3000 rows of R_FU), each the median of ``--repeats`` after a warm-up; the row count at which
  the dense one stops paying is ``rheograph.graphs.batched_solve.DENSE_MAX_PARTICLES``'s measure.
* ``e``: with ``--device cuda``, the CPU figures of a and d in the same run (with ``--cpu-fold`` also b's
  fold 0 with the demo's settings), with 2 torch threads and 2 graph processes, as on a 2-core machine.

The parts run in the order a, d, f, b, c (the quickest first).

Each part's results are written to ``--out`` as soon as it ends (a run stopped by a time limit keeps the
finished parts). Missing optional packages (scikit-sparse: the solver falls back to qdldl) change the
physics-input times, which the JSON records with the packages found.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import platform
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import numpy as np  # noqa: E402
import torch  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
PARTS = ("a", "b", "c", "d", "e", "f")
N400_FILES = "data/paper/multirun/N400_phi0.76_*/trajectory.h5"
N2000_FILE = "data/paper/multirun/N2000_phi0.76_s10_seed1_d0.002_implicit/trajectory.h5"
N20000_FILE = "data/large_n/multirun/N20000_phi0.76_s10_seed1_d0.002_implicit/trajectory.h5"
# the demo's settings and experiment=demo_gpu's (conf/experiment/demo_gpu.yaml)
SETTINGS = {"demo": {"batch_size": 32, "lr": 5.0e-3}, "demo_gpu": {"batch_size": 128, "lr": 1.0e-2}}
SCORES = ("test/r2_log_eta", "test/r2_log_pressure", "test/r2_z_mu")


def quiet_lightning() -> None:
    """Lightning's per-trainer banners (devices found, tips) off: the progress lines are the output."""
    import logging

    for name in ("lightning.pytorch", "lightning.fabric", "lightning"):
        logging.getLogger(name).setLevel(logging.WARNING)


def progress(text: str) -> None:
    print(f"[{time.strftime('%H:%M:%S')}] {text}", flush=True)


def synchronize(device: torch.device) -> None:
    if device.type == "cuda":
        torch.cuda.synchronize(device)


def timed(fn, device: torch.device, repeats: int, warm_up: bool = True) -> tuple[float, list[float], object]:
    """(median seconds, every repeat's seconds, last result) of ``fn()``, after one warm-up call."""
    result = fn() if warm_up else None
    times = []
    for _ in range(repeats):
        synchronize(device)
        start = time.perf_counter()
        result = fn()
        synchronize(device)
        times.append(time.perf_counter() - start)
    return statistics.median(times), times, result


class Results:
    """The JSON document, rewritten whole (through a temporary file) after every part."""

    def __init__(self, path: Path, meta: dict):
        self.path, self.data = path, {"meta": meta, "parts": {}}
        self.write()

    def set(self, part: str, value) -> None:
        self.data["parts"][part] = value
        self.write()

    def write(self) -> None:
        tmp = self.path.with_name(self.path.name + ".tmp")
        tmp.write_text(json.dumps(self.data, indent=1))
        tmp.replace(self.path)


def environment(device: torch.device, args) -> dict:
    import importlib.util

    import lightning
    import torch_geometric

    info = {
        "device": str(device),
        "device_name": torch.cuda.get_device_name(device) if device.type == "cuda" else platform.processor(),
        "cpu_count": os.cpu_count(),
        "torch": torch.__version__,
        "lightning": lightning.__version__,
        "torch_geometric": torch_geometric.__version__,
        "scikit_sparse": importlib.util.find_spec("sksparse") is not None,
        "quick": args.quick,
        "repeats": args.repeats,
        "workers": args.workers,
        "cpu_side_threads": 2,
        "torch_threads": torch.get_num_threads(),
        "started": time.strftime("%Y-%m-%d %H:%M:%S"),
    }
    return info


def compose_demo(cache_dir: Path, accelerator: str, overrides=()):
    from hydra import compose, initialize_config_dir

    with initialize_config_dir(config_dir=str(ROOT / "conf"), version_base="1.3"):
        return compose(
            config_name="train",
            overrides=[
                "experiment=demo",
                f"data.cache_dir={cache_dir}",
                f"trainer.accelerator={accelerator}",
                "trainer.enable_progress_bar=false",
                "~logger",
                *overrides,
            ],
        )


def accelerator_of(device: torch.device) -> str:
    return "gpu" if device.type == "cuda" else "cpu"


def build_cache(cache_dir: Path) -> dict:
    """The demo's graph cache built into ``cache_dir`` (one resistance solve per snapshot, this process)."""
    import glob

    from hydra.utils import instantiate

    from rheograph.graphs.dataset import snapshot_graphs
    from rheograph.learn.train import graph_settings

    cfg = compose_demo(cache_dir, "cpu")
    # the simulator's kernels compiled (or loaded from numba's cache) first: not part of the build
    start = time.perf_counter()
    first = one_snapshot(sorted(glob.glob(str(ROOT / N400_FILES)))[0])
    snapshot_graphs(first, graph_settings(cfg), 0, training=False)
    compile_seconds = time.perf_counter() - start
    start = time.perf_counter()
    dm = instantiate(cfg.data, graph=graph_settings(cfg), fold=0, _convert_="all")
    dm.setup()
    return {
        "seconds": time.perf_counter() - start,
        "graphs": len(dm.dataset),
        "compile_seconds": compile_seconds,
    }


class EpochTimer:
    """Lightning callback: seconds of every training epoch (its steps, not the validation after it)."""

    def __init__(self, device: torch.device):
        import lightning as L

        class _Timer(L.Callback):
            def on_train_epoch_start(inner, trainer, module):
                synchronize(device)
                inner.start = time.perf_counter()

            def on_train_epoch_end(inner, trainer, module):
                # validation is off (limit_val_batches=0): the epoch's batches and steps end here
                synchronize(device)
                self.seconds.append(time.perf_counter() - inner.start)

        self.seconds: list[float] = []
        self.callback = _Timer()


def epoch_times(cache_dir: Path, device: torch.device, repeats: int) -> list[dict]:
    """Part a: s/epoch of fold 0 for the per-batch loader and the device-resident sets, batch 32 / 128."""
    import lightning as L

    from rheograph.learn.train import graph_settings, setup_fold

    rows = []
    for batch_size in (32, 128):
        for resident in (False, True):
            cfg = compose_demo(
                cache_dir,
                accelerator_of(device),
                [f"data.batch_size={batch_size}", f"data.device_resident={str(resident).lower()}"],
            )
            L.seed_everything(0, verbose=False)
            dm, module = setup_fold(cfg, 0, graph_settings(cfg))
            timer = EpochTimer(device)
            trainer = L.Trainer(
                max_epochs=1 + repeats,
                accelerator=accelerator_of(device),
                devices=1,
                logger=False,
                enable_checkpointing=False,
                enable_progress_bar=False,
                enable_model_summary=False,
                num_sanity_val_steps=0,
                limit_val_batches=0,
                callbacks=[timer.callback],
            )
            trainer.fit(module, datamodule=dm)
            measured = timer.seconds[1:]  # after the warm-up epoch
            row = {
                "batch_size": batch_size,
                "loader": "device-resident" if resident else "PyG per batch",
                "train_graphs": int(len(dm.train_idx)),
                "seconds_per_epoch": statistics.median(measured),
                "epochs": measured,
            }
            progress(
                f"  a: batch {batch_size}, {row['loader']}: {row['seconds_per_epoch'] * 1e3:.0f} ms/epoch"
            )
            rows.append(row)
    return rows


def fold_runs(cache_dir: Path, device: torch.device, folds: list[int], epochs: int, work: Path) -> list[dict]:
    """Part b: each fold trained for ``epochs`` with the demo's and demo_gpu's batch size and rate."""
    import rheograph.learn.train as train_module

    rows = []
    for name, choice in SETTINGS.items():
        cfg = compose_demo(
            cache_dir,
            accelerator_of(device),
            [
                f"data.batch_size={choice['batch_size']}",
                f"model.optimizer.lr={choice['lr']}",
                f"trainer.max_epochs={epochs}",
                "fold_workers=1",
                "report=false",
                f"fold={list(folds)}".replace(" ", ""),
            ],
        )
        walls = {}
        original = train_module.train_fold

        def timed_fold(cfg, run_dir, k, settings, extra_callbacks=(), _walls=walls, _original=original):
            start = time.perf_counter()
            out = _original(cfg, run_dir, k, settings, extra_callbacks)
            _walls[k] = time.perf_counter() - start
            return out

        run_dir = work / f"b_{name}_{device.type}"
        shutil.rmtree(run_dir, ignore_errors=True)
        train_module.train_fold = timed_fold
        try:
            train_module.train_folds(cfg, run_dir)
        finally:
            train_module.train_fold = original
        metrics = json.loads((run_dir / "metrics.json").read_text())
        for result in metrics["folds"]:
            k = result["fold"]
            row = {
                "settings": name,
                **choice,
                "epochs": epochs,
                "fold": k,
                "wall_seconds": walls[k],
                **{key.removeprefix("test/"): result.get(key) for key in SCORES},
            }
            progress(
                f"  b: {name} fold {k}: {walls[k]:.1f} s, R² "
                + " / ".join(f"{row[key.removeprefix('test/')]:.4f}" for key in SCORES)
            )
            rows.append(row)
    return rows


def end_to_end(cache_dir: Path, device: torch.device, work: Path, quick: bool) -> dict:
    """Part c: the five-fold demo through ``train.py`` in a fresh process on the device (cache built)."""
    run_dir = work / f"c_{device.type}"
    shutil.rmtree(run_dir, ignore_errors=True)
    # on a GPU what its users run (experiment=demo_gpu: the GPU trainer, batch 128); on the CPU the demo
    # in one fold process (its two-process wall is in docs/validation/surrogate_cost.md)
    settings = ["experiment=demo_gpu"] if device.type == "cuda" else ["experiment=demo", "fold_workers=1"]
    command = [
        sys.executable,
        str(ROOT / "train.py"),
        *settings,
        f"data.cache_dir={cache_dir}",
        "~logger",
        f"hydra.run.dir={run_dir}",
    ]
    if quick:
        command += ["trainer.max_epochs=2", "fold=[0,1]"]
    env = {**os.environ, "PYTHONPATH": str(ROOT / "src")}
    start = time.perf_counter()
    done = subprocess.run(command, cwd=ROOT, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - start
    if done.returncode != 0:
        return {"error": (done.stderr or done.stdout).strip().splitlines()[-1:], "wall_seconds": wall}
    metrics = json.loads((run_dir / "metrics.json").read_text())
    return {
        "command": " ".join(command[1:]),
        "wall_seconds": wall,
        "folds": len(metrics["folds"]),
        **{key.removeprefix("test/"): metrics["mean"].get(key) for key in SCORES},
    }


def repeated_snapshots(files: list[str], count: int):
    """``count`` N = 400 snapshots of one state point's runs (the committed ones, repeated), as one
    ``Snapshots`` of the first file's suspension."""
    from rheograph.io.snapshots import read_snapshots

    first = read_snapshots(files[0])
    positions = np.concatenate([read_snapshots(f).positions for f in files if _same_box(f, first)])
    reps = int(np.ceil(count / len(positions)))
    positions = np.tile(positions, (reps, 1, 1))[:count]
    offsets = np.resize(first.le_offset, count)
    return dataclasses.replace(
        first,
        positions=positions,
        le_offset=offsets,
        strain=np.resize(first.strain, count),
        targets=np.resize(first.targets, (count, 3)),
        jammed=np.resize(first.jammed, count),
        contacts=None,
        source=f"{count} snapshots of {len(files)} runs (repeated)",
    )


def _same_box(path: str, first) -> bool:
    from rheograph.io.snapshots import read_snapshots

    snaps = read_snapshots(path)
    return np.allclose(snaps.radii, first.radii) and (snaps.lx, snaps.ly) == (first.lx, first.ly)


def one_snapshot(path: str):
    from rheograph.io.snapshots import read_snapshots

    snaps = read_snapshots(path)
    last = len(snaps) - 1
    return dataclasses.replace(
        snaps,
        positions=snaps.positions[last:],
        le_offset=snaps.le_offset[last:],
        strain=snaps.strain[last:],
        targets=snaps.targets[last:],
        jammed=snaps.jammed[last:],
        contacts=None,
    )


def prediction(
    device: torch.device, workers: int, repeats: int, quick: bool, cpu_side: bool = False
) -> list[dict]:
    """Part d: physics inputs (graphs) and forward passes of the shipped models, timed apart.
    ``cpu_side`` (part e): the forward passes timed once without a warm-up (on the CPU there is nothing
    to warm, and 1000 snapshots take tens of seconds), and predict_snapshots (their sum) not timed."""
    import glob
    import io
    from contextlib import redirect_stderr

    from rheograph.graphs.dataset import snapshot_graphs
    from rheograph.learn.bundle import predict_dataset
    from rheograph.learn.predict import PREDICT_NODE_BUDGET, load_model

    cases = [
        (
            "N400_phi0.76",
            "N = 400",
            repeated_snapshots(sorted(glob.glob(str(ROOT / N400_FILES))), 20 if quick else 1000),
        )
    ]
    cases.append(("N2000_phi0.76", "N = 2000", one_snapshot(str(ROOT / N2000_FILE))))
    if not quick:
        cases.append(("N2000_phi0.76", "N = 20 000", one_snapshot(str(ROOT / N20000_FILE))))
    rows = []
    for model_name, label, snaps in cases:
        model = load_model(model_name, device=device, workers=workers)
        numerics = model.solve_numerics(snaps.phi, snaps.n_particles)

        solve_device = model.physics_device(snaps)

        def physics(model=model, snaps=snaps, numerics=numerics, solve_device=solve_device):
            return snapshot_graphs(
                snaps,
                model.settings,
                0,
                numerics,
                training=False,
                workers=model.workers,
                solve_device=solve_device,
            )

        # the large snapshot's solve takes seconds: two timed calls, the kernels compiled by the others
        large = snaps.n_particles >= 10_000
        physics_s, physics_all, graphs = timed(
            physics, torch.device("cpu"), 2 if large else repeats, warm_up=not large
        )
        per_pass = max(1, PREDICT_NODE_BUDGET // snaps.n_particles)

        def forward(model=model, graphs=graphs, per_pass=per_pass):
            return [
                predict_dataset(m, graphs, batch_size=per_pass, device=model.device)[0]
                for m, _, _ in model.models
            ]

        forward_s, forward_all, _ = timed(forward, device, 1 if cpu_side else repeats, warm_up=not cpu_side)

        def whole(model=model, snaps=snaps):
            with redirect_stderr(io.StringIO()):  # the out-of-domain warning of the N = 20 000 snapshot
                return model.predict_snapshots(snaps)

        whole_s = None if cpu_side else timed(whole, device, 1, warm_up=False)[0]
        row = {
            "case": label,
            "model": model_name,
            "snapshots": len(snaps),
            "n_particles": int(snaps.n_particles),
            "fold_models": len(model.models),
            "device": str(device),
            "workers": workers,
            "physics_solver": "sparse, CPU" if solve_device is None else f"dense batches, {solve_device}",
            "physics_seconds": physics_s,
            "physics_all": physics_all,
            "forward_seconds": forward_s,
            "forward_all": forward_all,
            "predict_snapshots_seconds": whole_s,
        }
        progress(
            f"  d: {label} x {len(snaps)} on {device} ({workers} graph processes): "
            f"physics {physics_s:.2f} s, forward {forward_s:.3f} s, predict_snapshots "
            + ("not timed" if whole_s is None else f"{whole_s:.2f} s")
        )
        rows.append(row)
    return rows


# part f's systems: (dimension, N, phi); a CPU stops at 3000 rows of R_FU (dense n^3/3 beyond is minutes)
CROSSOVER_SIZES = (
    (2, 400, 0.76),
    (2, 1000, 0.76),
    (2, 2000, 0.76),
    (2, 4000, 0.76),
    (3, 500, 0.56),
    (3, 1000, 0.56),
    (3, 2000, 0.56),
)
CPU_DENSE_ROWS = 3000


def solver_crossover(device: torch.device, repeats: int, quick: bool) -> list[dict]:
    """Part f: one resistance problem solved by the sparse Cholesky (one CPU core) and, per problem, by
    the dense batched Cholesky on ``device`` (a batch of copies of it, as many as half a GB of dense
    matrices holds, at least 2), for each of CROSSOVER_SIZES: a fresh configuration stepped 5 times
    (lubricated gaps; the pattern of a sheared one)."""
    from rheograph.graphs.batched_solve import DenseBatchSolver
    from rheograph.sim import SimParams, Simulation
    from rheograph.sim.integrator3d import Simulation3D
    from rheograph.sim.params3d import SimParams3D

    sizes = ((2, 100, 0.76), (3, 60, 0.56)) if quick else CROSSOVER_SIZES
    rows = []
    for dim, n, phi in sizes:
        n_dof = n * (3 if dim == 2 else 6)
        if device.type == "cpu" and n_dof > CPU_DENSE_ROWS and not quick:
            continue
        params = (SimParams if dim == 2 else SimParams3D)(n_particles=n, phi=phi, stress=10.0, seed=1)
        sim = (Simulation if dim == 2 else Simulation3D)(params)
        for _ in range(5):
            sim.step()
        lp = sim.prepare_step()
        with cpu_threads(1):
            sparse_s, _, _ = timed(lambda sim=sim, lp=lp: sim.solve_linear(lp), torch.device("cpu"), repeats)
        batch = max(2, min(64, 2**29 // (3 * 8 * n_dof * n_dof)))
        solver = DenseBatchSolver(device)
        dense_s, _, _ = timed(
            lambda sim=sim, lp=lp, solver=solver, batch=batch: solver([sim] * batch, [lp] * batch),
            device,
            repeats,
        )
        row = {
            "dim": dim,
            "n_particles": n,
            "n_dof": n_dof,
            "nonzeros": int(sim.pattern()[1].size),
            "sparse_ms": sparse_s * 1e3,
            "dense_batch": batch,
            "dense_ms_per_problem": dense_s / batch * 1e3,
            "device": str(device),
        }
        progress(
            f"  f: {dim}D N = {n} ({n_dof} rows): sparse {row['sparse_ms']:.2f} ms, dense on {device} "
            f"{row['dense_ms_per_problem']:.2f} ms per problem (batches of {batch})"
        )
        rows.append(row)
    return rows


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--device", choices=("cpu", "cuda"), default="cuda")
    ap.add_argument("--out", required=True, help="the JSON results (rewritten after every part)")
    ap.add_argument("--parts", default=",".join(PARTS), help="comma-separated subset of a,b,c,d,e,f")
    ap.add_argument("--quick", action="store_true", help="tiny sizes: a smoke run of every part")
    ap.add_argument(
        "--repeats", type=int, default=None, help="timed repeats after the warm-up (default 3, quick 1)"
    )
    ap.add_argument(
        "--workers", type=int, default=None, help="graph processes of part d (default: the cores)"
    )
    ap.add_argument("--folds", default=None, help="folds of part b (default 0,1,2,3,4; quick 0)")
    ap.add_argument(
        "--cpu-fold", action="store_true", help="part e also trains fold 0 of b on the CPU (about a minute)"
    )
    ap.add_argument("--work", default=None, help="scratch directory (default: a temporary one, removed)")
    args = ap.parse_args(argv)
    parts = [p for p in args.parts.split(",") if p]
    unknown = sorted(set(parts) - set(PARTS))
    if unknown:
        ap.error(f"--parts: unknown {unknown}; allowed {list(PARTS)}")
    if args.device == "cuda" and not torch.cuda.is_available():
        ap.error("--device cuda: no CUDA GPU is visible to this process")
    device = torch.device(args.device)
    args.repeats = args.repeats or (1 if args.quick else 3)
    args.workers = args.workers or max(1, min(16, os.cpu_count() or 1))
    folds = [int(k) for k in args.folds.split(",")] if args.folds else ([0] if args.quick else list(range(5)))
    epochs = 2 if args.quick else 60
    os.chdir(ROOT)
    quiet_lightning()
    work = Path(args.work) if args.work else Path(tempfile.mkdtemp(prefix="rheograph_gpu_bench_"))
    work.mkdir(parents=True, exist_ok=True)
    cache_dir = work / "cache"
    results = Results(Path(args.out).resolve(), environment(device, args))
    progress(f"device {device}, parts {parts}, scratch {work}")
    try:
        if set(parts) & {"a", "b", "c"}:  # the training parts read the demo set's graphs
            progress("graph cache (one resistance solve per snapshot, one process)")
            results.set("cache", build_cache(cache_dir))
            progress(f"  cache: {results.data['parts']['cache']['seconds']:.1f} s")
        on_cpu = device.type == "cuda" and "e" in parts
        if "a" in parts:
            progress(f"part a: s/epoch on {device}")
            results.set("a", {str(device): epoch_times(cache_dir, device, args.repeats)})
            if on_cpu:
                progress("part e (a on the CPU, 2 threads)")
                with cpu_threads(2):
                    results.data["parts"]["a"]["cpu"] = epoch_times(
                        cache_dir, torch.device("cpu"), args.repeats
                    )
                results.write()
        if "d" in parts:
            progress(f"part d: prediction on {device}, {args.workers} graph processes")
            results.set(
                "d",
                {
                    str(device): prediction(
                        device, args.workers, args.repeats if not args.quick else 1, args.quick
                    )
                },
            )
            if on_cpu:
                progress("part e (d on the CPU, 2 threads, 2 graph processes)")
                with cpu_threads(2):
                    results.data["parts"]["d"]["cpu"] = prediction(
                        torch.device("cpu"), 2, 1, args.quick, cpu_side=True
                    )
                results.write()
        if "f" in parts:
            progress(f"part f: sparse solves on one CPU core against dense batches on {device}")
            results.set("f", solver_crossover(device, args.repeats, args.quick))
        if "b" in parts:
            progress(f"part b: folds {folds}, {epochs} epochs, on {device}")
            results.set("b", {str(device): fold_runs(cache_dir, device, folds, epochs, work)})
        if "c" in parts:
            progress(f"part c: train.py end to end on {device}")
            results.set("c", {str(device): end_to_end(cache_dir, device, work, args.quick)})
            progress(
                f"  c: {results.data['parts']['c'][str(device)].get('wall_seconds', float('nan')):.1f} s"
            )
        if on_cpu and "b" in parts and args.cpu_fold:
            progress("part e (b, fold 0 with the demo's settings, on the CPU, 2 threads)")
            with cpu_threads(2):
                results.data["parts"]["b"]["cpu"] = fold_runs_one(cache_dir, epochs, work)
            results.write()
    finally:
        results.data["meta"]["finished"] = time.strftime("%Y-%m-%d %H:%M:%S")
        results.write()
        if not args.work:
            shutil.rmtree(work, ignore_errors=True)
    progress(f"results: {args.out}")


def fold_runs_one(cache_dir: Path, epochs: int, work: Path) -> list[dict]:
    """Part e of b: fold 0, the demo's settings, on the CPU."""
    saved = dict(SETTINGS)
    SETTINGS.pop("demo_gpu")
    try:
        return fold_runs(cache_dir, torch.device("cpu"), [0], epochs, work)
    finally:
        SETTINGS.update(saved)


class cpu_threads:
    """Context: torch on ``n`` threads (a 2-core machine's share), restored after."""

    def __init__(self, n: int):
        self.n = n

    def __enter__(self):
        self.before = torch.get_num_threads()
        torch.set_num_threads(self.n)

    def __exit__(self, *exc):
        torch.set_num_threads(self.before)


if __name__ == "__main__":
    main()
