"""Surrogate cost: what training costs, what makes it cheaper, and accuracy against size and speed.
All on the committed paper-scale set (held-out whole trajectories, ``data.split=grouped``), this machine.

    OMP_WAIT_POLICY=PASSIVE python -m bench.train_speed levers    # s/epoch of each speed lever, one fold
    OMP_WAIT_POLICY=PASSIVE python -m bench.train_speed accuracy  # time to accuracy, before/after, N=400/2000
    OMP_WAIT_POLICY=PASSIVE python -m bench.train_speed pareto    # R² vs inference ms and training minutes
    OMP_WAIT_POLICY=PASSIVE python -m bench.train_speed folds     # K-fold wall time: fold processes vs one
    OMP_WAIT_POLICY=PASSIVE python -m bench.train_speed inference # per-snapshot prediction vs simulation

Each subcommand writes its marked section of docs/validation/surrogate_cost.md (``--no-write``: print
only) and keeps its raw results in docs/results/train_speed/<subcommand>.json; ``--reuse`` re-renders
from that file.  The records of ``accuracy`` and ``pareto`` (docs/results/bench/train_speed_<subcommand>
.json) keep the numbers of their figures too, drawn from them (as by ``python -m bench.render``).

* ``levers``: seconds per training epoch (median of ``--repeats`` epochs after one warm-up epoch, one
  thread) of the default model on fold 0's training graphs for one lever at a time: ``torch.compile``
  (dynamic shapes), batches collated once (fixed batches, order shuffled) instead of every epoch, batch
  size, layer instead of batch normalisation, and the per-epoch share of collation.
* ``accuracy``: wall time until the held-out-trajectory R² (log η_r, log Π, Z_μ; the test fold, evaluated
  after every epoch by a callback whose own time is not counted) first reaches 0.9, 0.95 and 0.99 of its
  final value (the model of the best validation epoch), for the configuration before the speed levers
  (constant learning rate, batch 16, early stopping with patience 50 up to 150 epochs) and after (cosine
  schedule over a fixed budget, the fastest batch size of ``levers``), at N = 400 and 2000.
* ``pareto``: one fold per model size (layers x width) and input variant, 60 epochs: held-out R² against
  the inference time per snapshot (graph building + forward pass, batched over the test fold, one thread)
  and the training minutes; the Pareto front and the paper's 2 x 64 marked in
  docs/figures/surrogate_pareto.png.
* ``inference``: predicting every snapshot of a trajectory file in one batched pass against the
  simulator's CPU seconds per decorrelated snapshot of every run of that (φ, N) (the speed-up as a ratio).
* ``folds``: the full K-fold training (``train.py`` path, report included) in one process with two threads
  against ``fold_workers=2`` processes with one thread each.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402
import torch  # noqa: E402

from bench.publishing import Section, publish, read_result_record
from bench.training import VARIANTS, benchmark_config  # noqa: E402
from rheograph.learn.module import regression_metrics  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "docs" / "results" / "train_speed"
SCORES = ("r2_log_eta", "r2_log_pressure", "r2_z_mu")
LABELS = {"r2_log_eta": "log η_r", "r2_log_pressure": "log Π", "r2_z_mu": "Z_μ"}
# before the speed levers: the paper's constant learning rate, batch 16, early stopping (patience 50)
BEFORE = ["model.scheduler=null", "callbacks.early_stopping.patience=50"]


def config(args, n, epochs, batch_size, extra=(), split="grouped", fold_workers=1):
    return benchmark_config(args.files, args.phi, n, split, epochs, fold_workers, batch_size, list(extra))


def setup_fold(cfg, k=0):
    """(datamodule, module) of fold ``k`` exactly as ``train.py`` builds them."""
    from rheograph.learn.train import graph_settings
    from rheograph.learn.train import setup_fold as train_setup_fold

    return train_setup_fold(cfg, k, graph_settings(cfg))


def held_out_scores(module, dm) -> dict:
    from rheograph.learn.bundle import predict_dataset

    pred, true, meta = predict_dataset(module, dm.dataset[torch.as_tensor(dm.test_idx)])
    flowing = ~meta["jammed"].astype(bool).ravel()
    metrics = regression_metrics(pred[flowing], true[flowing])
    return {key: metrics[key] for key in SCORES}


class HeldOutCurve:
    """Lightning callback: held-out R² after every training epoch against training wall seconds (the
    callback's own evaluation time is excluded)."""

    def __new__(cls, dm):
        import lightning as L

        class _Curve(L.Callback):
            def __init__(self):
                self.rows, self.spent, self.start = [], 0.0, None

            def on_train_start(self, trainer, module):
                self.start = time.perf_counter()

            def on_validation_epoch_end(self, trainer, module):
                if trainer.sanity_checking:
                    return
                t0 = time.perf_counter()
                training = module.training
                scores = held_out_scores(module, dm)
                module.train(training)
                self.rows.append(
                    {"epoch": trainer.current_epoch, "seconds": t0 - self.start - self.spent, **scores}
                )
                self.spent += time.perf_counter() - t0

        return _Curve()


def fit_fold(cfg, k=0, curve=False):
    """Train fold ``k``; returns (held-out scores of the best validation epoch, train seconds, curve rows,
    module, datamodule)."""
    import lightning as L
    from hydra.utils import instantiate

    L.seed_everything(int(cfg.seed) + k, workers=True)
    dm, module = setup_fold(cfg, k)
    callbacks = [instantiate(c) for c in cfg.callbacks.values()]
    tracker = HeldOutCurve(dm) if curve else None
    tmp = Path(tempfile.mkdtemp(prefix="train_speed_"))  # lightning's checkpoints of this fold
    trainer = instantiate(
        cfg.trainer,
        callbacks=callbacks + ([tracker] if tracker else []),
        logger=False,
        default_root_dir=str(tmp),
        enable_model_summary=False,
    )
    t0 = time.perf_counter()
    trainer.fit(module, datamodule=dm)
    seconds = time.perf_counter() - t0 - (tracker.spent if tracker else 0.0)
    ckpt = next(c for c in callbacks if hasattr(c, "best_model_path"))
    state = torch.load(ckpt.best_model_path, map_location="cpu", weights_only=True)["state_dict"]
    module.load_state_dict(state)
    shutil.rmtree(tmp, ignore_errors=True)
    return held_out_scores(module, dm), seconds, (tracker.rows if tracker else []), module, dm


# ---- levers -------------------------------------------------------------------------------------------
def epoch_seconds(net, batches, repeats):
    """Median seconds of one training epoch of ``net`` over ``batches`` (a callable returning the epoch's
    batches, so that collation can be inside the timed region), Adam, one warm-up epoch."""
    opt = torch.optim.Adam(net.parameters(), lr=1e-3)
    times = []
    for _ in range(repeats + 1):
        t0 = time.perf_counter()
        for b in batches():
            z = net(b.x, b.edge_index, b.edge_attr, b.batch, b.u, b.area)
            loss = torch.nn.functional.smooth_l1_loss(z, b.y)
            opt.zero_grad()
            loss.backward()
            opt.step()
        times.append(time.perf_counter() - t0)
    return float(np.median(times[1:] if repeats else times))


def levers(args) -> list[str]:
    from torch_geometric.loader import DataLoader

    torch.set_num_threads(1)
    rows = []
    for n in args.n:
        cfg = config(args, n, 1, 32)
        dm, module = setup_fold(cfg)
        train = dm.dataset[torch.as_tensor(dm.train_idx)]
        net = module.net.train()
        for batch_size in args.batch_sizes:
            loader = DataLoader(train, batch_size=batch_size, shuffle=True)
            fresh = epoch_seconds(net, lambda loader=loader: loader, args.repeats)
            fixed = list(loader)
            rng = np.random.default_rng(0)
            once = epoch_seconds(
                net, lambda f=fixed, r=rng: [f[i] for i in r.permutation(len(f))], args.repeats
            )
            t0 = time.perf_counter()
            for _ in range(args.repeats):
                list(loader)
            collate = (time.perf_counter() - t0) / args.repeats
            rows.append(
                dict(n=n, lever=f"batch {batch_size}, collated every epoch", seconds=fresh, graphs=len(train))
            )
            rows.append(
                dict(n=n, lever=f"batch {batch_size}, collated once", seconds=once, graphs=len(train))
            )
            rows.append(
                dict(n=n, lever=f"batch {batch_size}: collation alone", seconds=collate, graphs=len(train))
            )
            print(rows[-3:], flush=True)
        # normalisation layer: layer norm per node (DeeperGCN) instead of batch norm (the paper's)
        _, layer_norm = setup_fold(config(args, n, 1, 32, ["model.net.norm=layer"]))
        loader = DataLoader(train, batch_size=32, shuffle=True)
        seconds = epoch_seconds(layer_norm.net.train(), lambda loader=loader: loader, args.repeats)
        rows.append(
            dict(n=n, lever="batch 32, layer norm instead of batch norm", seconds=seconds, graphs=len(train))
        )
        print(rows[-1], flush=True)
        if args.compile:
            fixed = list(DataLoader(train, batch_size=32, shuffle=True))
            t0 = time.perf_counter()
            compiled = torch.compile(net, dynamic=True)
            first = epoch_seconds(compiled, lambda f=fixed: f, 0)
            rows.append(
                dict(
                    n=n,
                    lever="batch 32, torch.compile(dynamic=True): first epoch (compiling)",
                    seconds=first,
                    graphs=len(train),
                )
            )
            steady = epoch_seconds(compiled, lambda f=fixed: f, args.repeats)
            rows.append(
                dict(n=n, lever="batch 32, torch.compile(dynamic=True)", seconds=steady, graphs=len(train))
            )
            print(rows[-2:], f"{time.perf_counter() - t0:.0f} s", flush=True)
    return rows


def render_levers(rows, args) -> Section:
    out = Section(
        "Seconds per training epoch of the default model (`model=resgcn_physics`, width 64, 2 layers) over "
        "fold 0's training graphs of φ = 0.76, one torch thread, median of "
        f"{args.repeats} epochs after a warm-up epoch.",
        "",
    )
    body = [
        [
            f"{r['n']}",
            r["lever"],
            f"{r['graphs']}",
            f"{r['seconds']:.2f}",
            f"{r['graphs'] / r['seconds']:.0f}",
        ]
        for r in rows
    ]
    out.table(["N", "lever", "training graphs", "s/epoch", "graphs/s"], body)
    out.add("", f"Command: `{command_line()}`")
    return out


# ---- time to accuracy -----------------------------------------------------------------------------------
def accuracy(args) -> list[dict]:
    torch.set_num_threads(1)
    rows = []
    for n in args.n:
        for label, epochs, batch, extra in (
            ("before", args.before_epochs, 16, BEFORE),
            ("after", args.epochs, None, []),  # benchmark_config's batch: the fastest per epoch at N
        ):
            cfg = config(args, n, epochs, batch, extra)
            scores, seconds, curve, _, dm = fit_fold(cfg, 0, curve=True)
            rows.append(
                dict(n=n, label=label, final=scores, seconds=seconds, curve=curve, graphs=len(dm.dataset))
            )
            print(n, label, scores, f"{seconds:.0f} s, {len(curve)} epochs", flush=True)
    return rows


def time_to(curve, key, target):
    for row in curve:
        if row[key] >= target:
            return row["seconds"]
    return float("nan")


def render_accuracy(rows, args) -> Section:
    out = Section(
        f"Fold 0 of 5 (held-out whole trajectories), φ = {args.phi}, one torch thread.  *before*: constant "
        "learning rate, batch 16, early stopping with patience 50 (at most "
        f"{args.before_epochs} epochs); *after*: cosine schedule over {args.epochs} epochs, batch 32 "
        "(N = 400) / 8 (N = 2000), the fastest per epoch in the levers table.  "
        "Final = held-out R² of the best validation epoch; t(x) = training wall seconds until the held-out "
        "R² first reaches x × final.",
        "",
    )
    body = []
    for r in rows:
        final = " / ".join(f"{r['final'][k]:.3f}" for k in SCORES)
        times = []
        for frac in (0.9, 0.95, 0.99):
            per = [time_to(r["curve"], k, frac * r["final"][k]) for k in SCORES]
            times.append("–" if any(np.isnan(per)) else f"{max(per):.0f}")
        body.append(
            [
                f"{r['n']}",
                f"{r['graphs']}",
                r["label"],
                f"{len(r['curve'])}",
                f"{r['seconds']:.0f}",
                final,
                *times,
            ]
        )
    header = ["N", "graphs", "config", "epochs run", "train s", "final R² log η_r / log Π / Z_μ", "t(0.9) s"]
    out.table(header + ["t(0.95) s", "t(0.99) s (slowest target)"], body)
    out.add(
        "",
        "Figure: [figures/time_to_accuracy.png](../figures/time_to_accuracy.png).",
        "",
        f"Command: `{command_line()}`",
    )
    return out


def accuracy_figure(rows, args) -> dict:
    """The numbers of docs/figures/time_to_accuracy.png (:func:`bench.figures.draw_time_to_accuracy`):
    per (N, configuration) the training minutes and the held-out R² of each target at every epoch."""
    runs = [
        {"n": r["n"], "label": r["label"], "minutes": [c["seconds"] / 60 for c in r["curve"]]}
        | {key: [c[key] for c in r["curve"]] for key in SCORES}
        for r in rows
    ]
    return {"runs": runs}


# ---- accuracy against model size and inference time ----------------------------------------------------
def inference_ms(module, dm, repeats=3) -> float:
    """Milliseconds per snapshot of one batched forward pass over the test fold (batch 64, one thread)."""
    from torch_geometric.loader import DataLoader

    test = dm.dataset[torch.as_tensor(dm.test_idx)]
    batches = list(DataLoader(test, batch_size=64))
    module.eval()
    times = []
    with torch.no_grad():
        for _ in range(repeats + 1):
            t0 = time.perf_counter()
            for b in batches:
                module(b)
            times.append(time.perf_counter() - t0)
    return 1e3 * float(np.median(times[1:])) / len(test)


def graph_build_ms(dm, repeats=3) -> float:
    """Milliseconds per snapshot to read a test trajectory file and turn its snapshots into graphs (edges,
    features, descriptors), median of ``repeats`` passes after a warm-up."""
    from rheograph.graphs.dataset import snapshot_graphs

    path = dm.files[int(dm.dataset.run_id[int(dm.test_idx[0])])]
    times = []
    for _ in range(repeats + 1):
        t0 = time.perf_counter()
        graphs = snapshot_graphs(path, dm.graph, 0)
        times.append((time.perf_counter() - t0) / len(graphs))
    return 1e3 * float(np.median(times[1:]))


def pareto(args) -> list[dict]:
    torch.set_num_threads(1)
    rows = []
    for spec in args.models:
        variant, _, size = spec.partition(":")
        layers, width = (int(v) for v in size.split("x"))
        extra = [*VARIANTS[variant], f"model.net.num_layers={layers}", f"model.net.hidden={width}"]
        if variant == "paper":
            extra.append("model.scheduler=null")
        cfg = config(args, 400, args.epochs, None, extra)
        scores, seconds, _, module, dm = fit_fold(cfg, 0)
        from rheograph.learn.model import count_parameters

        rows.append(
            dict(
                variant=variant,
                layers=layers,
                width=width,
                parameters=count_parameters(module),
                scores=scores,
                train_minutes=seconds / 60,
                forward_ms=inference_ms(module, dm),
                build_ms=graph_build_ms(dm),
            )
        )
        print(rows[-1], flush=True)
    return rows


def pareto_figure(rows, args) -> dict:
    """The numbers of docs/figures/surrogate_pareto.png (:func:`bench.figures.draw_surrogate_pareto`): per
    model its variant, size, held-out R² of each target, ms per snapshot (graph building + forward) and
    training minutes."""
    keys = ("variant", "layers", "width", "scores", "train_minutes")
    return {
        "phi": args.phi,
        "models": [{k: r[k] for k in keys} | {"ms": r["forward_ms"] + r["build_ms"]} for r in rows],
    }


def render_pareto(rows, args) -> Section:
    out = Section(
        f"Fold 0 of 5 (held-out whole trajectories), φ = {args.phi}, N = 400, {args.epochs} epochs (cosine; "
        "the paper variant with its constant rate), batch 32, one torch thread.  ms per snapshot = graph "
        "building + forward pass batched over the test fold (batch 64).  The paper's size is 2 × 64.",
        "",
    )
    body = []
    for r in rows:
        s = r["scores"]
        body.append(
            [r["variant"], f"{r['layers']} × {r['width']}", f"{r['parameters']}", f"{s['r2_log_eta']:.3f}"]
            + [f"{s['r2_log_pressure']:.3f}", f"{s['r2_z_mu']:.3f}", f"{r['build_ms']:.2f}"]
            + [f"{r['forward_ms']:.2f}", f"{r['train_minutes']:.1f}"]
        )
    header = ["inputs", "layers × width", "parameters", "R² log η_r", "R² log Π", "R² Z_μ", "build ms"]
    out.table(header + ["forward ms", "train min"], body)
    out.add(
        "",
        "Figure: [figures/surrogate_pareto.png](../figures/surrogate_pareto.png).",
        "",
        "Command (rows accumulate in docs/results/train_speed/pareto.json): "
        "`python -m bench.train_speed pareto "
        f"--models {' '.join(args.models)}`",
    )
    return out


# ---- speed-up over the simulator ------------------------------------------------------------------------
def inference(args) -> list[dict]:
    """Per N: ms per snapshot to predict every snapshot of a trajectory file in one batched pass (read +
    graph building + forward; one model and the 5-fold ensemble), against the simulator's CPU seconds per
    decorrelated snapshot (median over every run of that phi and N)."""
    from torch_geometric.loader import DataLoader

    from rheograph.analysis.dataset_card import cpu_seconds_per_decorrelated_snapshot
    from rheograph.graphs.dataset import snapshot_graphs

    torch.set_num_threads(1)
    rows = []
    for n in args.n:
        dm, module = setup_fold(config(args, n, 1, 32))
        module.eval()
        files = sorted({dm.files[int(dm.dataset.run_id[int(i)])] for i in dm.test_idx})[: args.files_per_n]
        snapshot_graphs(files[0], dm.graph, 0)  # numba compilation outside the timed region
        # the simulator's cost over every run of this (phi, N), all stresses: the test files are a subset
        sim = [cpu_seconds_per_decorrelated_snapshot(path) for path in dm.files]
        builds, forwards = [], []
        for _ in range(args.repeats):  # medians over passes: timings on this shared machine are noisy
            build, forward, count = 0.0, 0.0, 0
            for path in files:
                t0 = time.perf_counter()
                graphs = snapshot_graphs(path, dm.graph, 0)
                t1 = time.perf_counter()
                with torch.no_grad():  # batches of about 25k particles: larger ones leave the cache (levers)
                    for b in DataLoader(graphs, batch_size=max(1, 25600 // n)):
                        module(b)
                build += t1 - t0
                forward += time.perf_counter() - t1
                count += len(graphs)
            builds.append(build)
            forwards.append(forward)
        build, forward = float(np.median(builds)), float(np.median(forwards))
        one = (build + forward) / count
        ensemble = (build + 5 * forward) / count
        rows.append(
            dict(
                n=n,
                files=len(files),
                snapshots=count,
                build_ms=1e3 * build / count,
                forward_ms=1e3 * forward / count,
                simulator_s=float(np.median(sim)),
                speedup_one=float(np.median(sim)) / one,
                speedup_ensemble=float(np.median(sim)) / ensemble,
            )
        )
        print(rows[-1], flush=True)
    return rows


def render_inference(rows, args) -> Section:
    out = Section(
        f"φ = {args.phi}, default model (2 × 64, `graph=physics_solve`: graph building includes the one "
        "resistance solve per snapshot), one thread: every snapshot of a trajectory file predicted "
        "in one pass (read + graph building, batched forward, batches of 64 N = 400 / 12 N = 2000 graphs), "
        f"test-fold files of fold 0, median of {args.repeats} passes.  "
        "Simulator: every run's recorded CPU s/strain × its 1/e decorrelation strain of log η_r (median "
        "over all runs of this (φ, N), every stress; implicit, disp_max 2e-3).",
        "",
    )
    body = [
        [f"{r['n']}", f"{r['files']}", f"{r['snapshots']}", f"{r['build_ms']:.2f}", f"{r['forward_ms']:.2f}"]
        + [f"{r['simulator_s']:.2f}", f"{r['speedup_one']:.0f}×", f"{r['speedup_ensemble']:.0f}×"]
        for r in rows
    ]
    header = ["N", "files timed", "snapshots", "build ms", "forward ms (1 model)"]
    header += ["simulator CPU s per decorrelated snapshot", "speed-up, 1 model", "speed-up, 5-model ensemble"]
    out.table(header, body)
    out.add("", f"Command: `{command_line()}`")
    return out


# ---- whole K-fold runs ------------------------------------------------------------------------------------
def folds(args) -> list[dict]:
    from rheograph.learn.train import train_folds

    rows = []
    for case in args.cases:
        try:
            n, workers = (int(v) for v in case.split(":"))
        except ValueError:
            raise SystemExit(f"--cases: expected N:processes (e.g. 400:2), got {case!r}") from None
        extra = ["threads=2"] if workers == 1 else []
        cfg = config(args, n, args.epochs, None, extra, fold_workers=workers)
        run_dir = RESULTS / f"folds_n{n}_w{workers}"
        shutil.rmtree(run_dir, ignore_errors=True)
        t0 = time.perf_counter()
        summary = train_folds(cfg, run_dir)
        minutes = (time.perf_counter() - t0) / 60
        split = json.loads((run_dir / "fold0_split.json").read_text())
        graphs = len(split["train"]) + len(split["val"]) + len(split["test"])
        rows.append(
            dict(
                n=n,
                workers=workers,
                minutes=minutes,
                graphs=graphs,
                scores={k: summary[f"test/{k}"] for k in SCORES},
            )
        )
        print(rows[-1], flush=True)
        shutil.rmtree(run_dir, ignore_errors=True)
    return rows


def render_folds(rows, args) -> Section:
    out = Section(
        f"All 5 folds (held-out whole trajectories, {args.epochs} epochs, cosine, batch 32 at N = 400, 8 at "
        f"N = 2000), φ = {args.phi}, "
        "the `train.py` path (baselines, bundles and report included), wall minutes on this 2-core machine.  "
        "Minutes per 380 graphs scales the measured time linearly with the number of graphs (the paper's "
        "set size).",
        "",
    )
    body = []
    for r in rows:
        layout = "1 × 2" if r["workers"] == 1 else f"{r['workers']} × 1"
        final = " / ".join(f"{r['scores'][k]:.3f}" for k in SCORES)
        body.append(
            [
                f"{r['n']}",
                f"{r['graphs']}",
                layout,
                f"{r['minutes']:.1f}",
                f"{r['minutes'] * 380 / r['graphs']:.1f}",
            ]
            + [final]
        )
    header = ["N", "graphs", "processes × threads", "wall min", "min per 380 graphs"]
    out.table(header + ["mean R² log η_r / log Π / Z_μ"], body)
    out.add("", f"Command: `{command_line()}`")
    return out


# the command that made the rows (set by main: with --reuse, the one saved with them)
COMMAND: list[str] = []


def command_line() -> str:
    if COMMAND:
        return COMMAND[0]
    return "python -m bench.train_speed " + " ".join(
        a for a in sys.argv[1:] if a not in ("--reuse", "--no-write")
    )


# the subcommands whose record holds the numbers of a figure too, and the function that picks them
FIGURE_DATA = {"accuracy": accuracy_figure, "pareto": pareto_figure}
RUNNERS = {
    "levers": (levers, render_levers),
    "accuracy": (accuracy, render_accuracy),
    "pareto": (pareto, render_pareto),
    "folds": (folds, render_folds),
    "inference": (inference, render_inference),
}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("what", choices=sorted(RUNNERS))
    ap.add_argument("--files", default="data/paper/index.json")
    ap.add_argument("--phi", type=float, default=0.76)
    ap.add_argument("--n", type=int, nargs="+", default=[400, 2000])
    ap.add_argument("--epochs", type=int, default=60)
    ap.add_argument("--before-epochs", type=int, default=150)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--batch-sizes", type=int, nargs="+", default=[8, 16, 32, 64])
    ap.add_argument("--no-compile", dest="compile", action="store_false")
    ap.add_argument(
        "--cases", nargs="+", default=["400:1", "400:2", "2000:2"], help="folds: N:fold_processes pairs"
    )
    ap.add_argument("--files-per-n", type=int, default=6, help="inference: trajectory files timed per N")
    ap.add_argument(
        "--models",
        nargs="+",
        default=[
            "physics:1x32",
            "physics:2x16",
            "physics:2x32",
            "physics:2x64",
            "physics:4x64",
            "physics:2x128",
            "physics_positions:2x64",
            "paper:2x64",
        ],
        help="variant:LAYERSxWIDTH",
    )
    ap.add_argument("--reuse", action="store_true", help="render the stored results again, no training")
    ap.add_argument("--no-write", action="store_true")
    args = ap.parse_args(argv)
    RESULTS.mkdir(parents=True, exist_ok=True)
    run, render = RUNNERS[args.what]
    store = RESULTS / f"{args.what}.json"
    if args.reuse:
        saved = json.loads(store.read_text())
        rows, args = saved["rows"], argparse.Namespace(**{**vars(args), **saved["args"]})
        # the command that made the rows (saved with them; before that, the one the published section quotes)
        COMMAND[:] = [saved.get("command") or read_result_record(f"train_speed_{args.what}")["command"]]
    else:
        rows = run(args)
        if args.what == "pareto" and store.exists():  # rows accumulate: a re-run model replaces its row
            key = lambda r: (r["variant"], r["layers"], r["width"])  # noqa: E731
            new = {key(r) for r in rows}
            rows = [r for r in json.loads(store.read_text())["rows"] if key(r) not in new] + rows
            args.models = [f"{r['variant']}:{r['layers']}x{r['width']}" for r in rows]
        store.write_text(
            json.dumps(
                {
                    "args": {k: v for k, v in vars(args).items() if k not in ("reuse", "no_write")},
                    "rows": rows,
                    "command": command_line(),
                },
                indent=1,
            )
        )
    figure = FIGURE_DATA.get(args.what)
    publish(
        f"train_speed_{args.what}",
        render(rows, args),
        not args.no_write,
        page="validation/surrogate_cost.md",
        record={"figure": figure(rows, args)} if figure else None,
        command=command_line(),
    )


if __name__ == "__main__":
    main()
