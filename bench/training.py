"""What the surrogate benchmarks share: the input variants they train (override lists of conf/) and the
training configuration they compose, with a fixed epoch budget, and resumed folds.

Variants: ``paper`` = graph=paper model=resgcn (the seed paper: geometric edge features, softmax
aggregation, mean pooling, positions only); ``physics_positions`` = physics-aware edge features, positions
only; ``physics`` = physics-aware features + imposed stress (graph input and CLM load); ``physics_solve`` =
``physics`` + the one-solve viscosity and the counted Z_μ, both targets learned as corrections to them
(graph=physics_solve, the default); ``physics_solve_uncorrected`` = the same inputs read through the head
(an earlier default); ``physics_mean_pool`` = ``physics`` with mean pooling and softmax aggregation;
``physics_layer_norm`` = ``physics`` with layer instead of batch normalisation; ``physics_pi_sigma0`` =
``physics`` learning Pi in sigma0 (graph.targets.pi.per_stress=false) with the weights that suited it
(2/5/2); ``<inputs>_tuned`` = the best trial of that input variant's Optuna study
(``conf/experiment/<inputs>_phi076_best.yaml``, its own batch size).  The comparison of these variants
(docs/validation/surrogate_accuracy.md) was made by a study script no longer in the package:
``git show 1128213:bench/surrogate_study.py``.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

from hydra import compose, initialize_config_dir  # noqa: E402

from rheograph.learn.train import train_folds  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
VARIANTS = {
    "paper": ["graph=paper", "model=resgcn"],
    "physics_positions": ["graph=physics_positions", "model=resgcn_physics"],
    "physics": ["graph=physics", "model=resgcn_physics"],
    "physics_solve": ["graph=physics_solve", "model=resgcn_physics"],
    # the default inputs as they were before the corrections became default
    "physics_solve_uncorrected": [
        "graph=physics_solve",
        "model=resgcn_physics",
        "graph.targets.eta_r.relative_to=null",
        "graph.targets.z_mu.relative_to=null",
    ],
    "physics_mean_pool": [
        "graph=physics",
        "model=resgcn_physics",
        "model.net.pool=mean",
        "model.net.aggr=softmax",
    ],
    "physics_layer_norm": ["graph=physics", "model=resgcn_physics", "model.net.norm=layer"],
    "physics_pi_sigma0": [
        "graph=physics",
        "model=resgcn_physics",
        "graph.targets.pi.per_stress=false",
        "model.loss_weights=[2.0,5.0,2.0]",
    ],
    # the best trial of each input variant's Optuna study (tune.py), with its batch size
    **{
        f"{v}_tuned": [f"experiment={v}_phi076_best"]
        for v in ("physics", "paper", "physics_positions", "physics_solve")
        if (ROOT / "conf" / "experiment" / f"{v}_phi076_best.yaml").exists()  # once its study has run
    },
}


def train_or_resume(cfg, run_dir: Path) -> None:
    """Train the folds into ``run_dir``, keeping folds an interrupted earlier invocation of the same
    configuration finished on the same data; a directory of another configuration or other data is
    replaced."""
    from rheograph.errors import OtherRunError

    try:
        train_folds(cfg, run_dir)
    except OtherRunError:
        shutil.rmtree(run_dir)
        train_folds(cfg, run_dir)


def benchmark_config(files, phi, n, split, epochs, fold_workers, batch_size=None, extra=()):
    """The training configuration every surrogate benchmark composes: one (phi, N), a fixed epoch budget
    (cosine schedule, best validation epoch kept), no logger.  Batch size (default): 32 graphs at
    N < 2000, 8 at N >= 2000 — the fastest per epoch (docs/validation/surrogate_cost.md: batches of 32
    N = 2000 graphs leave the cache and train 1.4x slower)."""
    if batch_size is None:
        batch_size = 8 if n >= 2000 else 32
    overrides = [
        f"data.files={files}",
        f"data.phi={phi}",
        f"data.n_particles={n}",
        f"data.split={split}",
        f"data.batch_size={batch_size}",
        f"trainer.max_epochs={epochs}",
        "trainer.enable_progress_bar=false",
        "callbacks.early_stopping.patience=1000",
        "~logger",
        f"fold_workers={fold_workers}",
        *extra,
    ]
    with initialize_config_dir(config_dir=str(ROOT / "conf"), version_base="1.3"):
        return compose(config_name="train", overrides=overrides)
