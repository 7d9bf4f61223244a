"""LightningModule: multitask Huber regression of (transformed eta_r, transformed Pi, Z_mu)."""

from __future__ import annotations

import functools
import inspect
import logging
import math
from collections.abc import Mapping

import lightning as L
import numpy as np
import torch
from torch import nn

from rheograph.errors import InputError
from rheograph.graphs.features import inverse_transform
from rheograph.graphs.targets import LEGACY_MODULE_KEYS, TargetSpec, from_legacy
from rheograph.learn.model import ResGCN
from rheograph.learn.nets import build_net, class_name, net_record

log = logging.getLogger("rheograph")

TARGET_NAMES = ("eta", "pressure", "z_mu")


def warmup_cosine(
    optimizer: torch.optim.Optimizer, max_epochs: int, warmup_epochs: int = 0
) -> torch.optim.lr_scheduler.LRScheduler:
    """Per-epoch learning-rate factor: a linear warm-up (epoch e < w: (e + 1) / (w + 1)), then a cosine
    decay to 0 at ``max_epochs`` (0.5 (1 + cos(pi (e - w) / (max_epochs - w)))), from torch's schedulers.
    Why: a fixed epoch budget replaces most of early stopping's patience (fewer epochs, same accuracy).
    ``warmup_epochs`` is capped at ``max_epochs - 1`` so that the decay always has an epoch."""
    if warmup_epochs < 0:
        raise InputError(f"model.scheduler.warmup_epochs={warmup_epochs} is invalid: allowed >= 0")
    total = max(1, int(max_epochs))
    warmup = min(int(warmup_epochs), total - 1)
    cosine = torch.optim.lr_scheduler.CosineAnnealingLR(optimizer, T_max=max(1, total - warmup))
    if warmup == 0:
        return cosine
    ramp = torch.optim.lr_scheduler.LinearLR(
        optimizer, start_factor=1.0 / (warmup + 1), end_factor=1.0, total_iters=warmup
    )
    return torch.optim.lr_scheduler.SequentialLR(optimizer, [ramp, cosine], milestones=[warmup])


def _describe(factory) -> str:
    """``torch.optim.Adam(lr=0.005, ...)`` for a partial, for messages."""
    if isinstance(factory, functools.partial):
        kwargs = ", ".join(f"{k}={v!r}" for k, v in factory.keywords.items())
        return f"{factory.func.__module__}.{factory.func.__qualname__}({kwargs})"
    return repr(factory)


def check_training_factories(optimizer, scheduler) -> None:
    """Build the optimiser (and the schedule) once on a dummy parameter, so that a bad setting (a NaN or
    negative learning rate, an unknown keyword) is refused by name before any graph is built."""
    try:
        built = optimizer([nn.Parameter(torch.zeros(1))])
    except (ValueError, TypeError) as err:
        raise InputError(f"model.optimizer={_describe(optimizer)} is invalid: {err}") from None
    if any(isinstance(v, float) and not math.isfinite(v) for v in built.defaults.values()):
        raise InputError(f"model.optimizer={_describe(optimizer)} is invalid: a value is not finite")
    if scheduler is not None:
        try:
            scheduler(built, max_epochs=2)
        except (ValueError, TypeError) as err:
            raise InputError(f"model.scheduler={_describe(scheduler)} is invalid: {err}") from None


def network_hparams(hparams: dict, module_class: type | None = None) -> dict:
    """The keys of ``hparams`` that ``module_class`` (``SurrogateModule`` or a subclass; their
    constructors' parameters together) takes: bundles of older versions also hold their optimiser
    settings, which a trained network does not need (as Lightning's ``load_from_checkpoint`` drops keys
    the constructor does not take)."""
    module_class = module_class or SurrogateModule
    own = inspect.signature(module_class.__init__).parameters
    if any(p.kind is inspect.Parameter.VAR_KEYWORD for p in own.values()):
        # a subclass passing **kwargs on: its own parameters and those of the classes it passes them to
        classes = [c for c in module_class.__mro__ if issubclass(c, SurrogateModule)]
        accepted = {name for c in classes for name in inspect.signature(c.__init__).parameters}
    else:  # an explicit signature: only what it takes (the hparams also hold its parent's)
        accepted = set(own)
    return {k: v for k, v in hparams.items() if k in accepted}


# the network options SurrogateModule took itself before ``model.net`` (model files of formats 2-4), at
# the defaults it gave them; the network was then always a ResGCN with three outputs
LEGACY_NET_OPTIONS = {
    "node_in": 2,
    "edge_in": 6,
    "hidden": 64,
    "num_layers": 2,
    "aggr": "softmax",
    "block": "res+",
    "dropout": 0.1,
    "pool": "mean",
    "global_in": 0,
    "head_layers": 1,
    "edge_readout": False,
    "norm": "batch",
    "global_mixing": "none",
}


def upgraded_hparams(hparams: Mapping, graph: Mapping | None = None) -> dict:
    """The module hyperparameters of a model of any version in the current form: the one adapter from
    earlier forms, for model files (rheograph.learn.bundle) and Lightning's ``load_from_checkpoint``
    (``SurrogateModule.on_load_checkpoint``) alike.  Without ``targets``, the target specification is read
    from the graph settings ``graph`` and the module's own earlier keys (rheograph.graphs.targets.
    from_legacy); without ``net``, the network is the ResGCN that the flat options (``hidden``,
    ``num_layers``, ... at their former defaults where absent) described.  A current record is returned
    as it is."""
    out = dict(hparams)
    if "targets" not in out and isinstance(graph, Mapping):
        targets = from_legacy(graph, out).to_config()
        out = {k: v for k, v in out.items() if k not in LEGACY_MODULE_KEYS}
        out.update(targets=targets, graph_inputs=list(graph.get("graph_inputs", ())))
    if "net" not in out:
        options = {key: out.pop(key, default) for key, default in LEGACY_NET_OPTIONS.items()}
        out["net"] = {"name": class_name(ResGCN), "kwargs": options}
    return out


def physical_targets(y_transformed: np.ndarray, targets: TargetSpec) -> np.ndarray:
    """Invert the target transforms of ``targets``: (G, 3) transformed -> (G, 3) [eta_r, Pi, Z_mu] in
    physical units."""
    y = np.asarray(y_transformed, dtype=np.float64)
    return np.stack(
        [
            inverse_transform(y[:, 0], targets.viscosity_scale),
            inverse_transform(y[:, 1], targets.pressure_scale),
            y[:, 2],
        ],
        axis=1,
    )


def r2_score(pred: np.ndarray, true: np.ndarray) -> float:
    """Coefficient of determination of ``pred`` against ``true`` (scikit-learn's); NaN where ``true``
    does not vary (undefined: scikit-learn would report 1 or -inf there) or ``pred`` is not finite."""
    from sklearn.metrics import r2_score as sklearn_r2

    true, pred = np.asarray(true, dtype=np.float64), np.asarray(pred, dtype=np.float64)
    if true.size < 2 or not np.ptp(true) > 0 or not np.isfinite(pred).all():
        return float("nan")  # (a NaN prediction, e.g. a physics row without its solve, scores NaN)
    return float(sklearn_r2(true, pred))


LOG_TARGETS = ("eta", "pressure")  # scored on a log scale too (seed paper), Z_mu only linearly


def regression_metrics(pred: np.ndarray, true: np.ndarray) -> dict:
    """Per target (G, 3) physical units: R^2, MAE, MAPE (skips |true| < 1e-8, e.g. Z_mu = 0) and the
    fraction within +-15 % (``within15``; for Z_mu within +-15 % or 0.05, so that Z_mu = 0 counts).

    For eta_r and Pi also ``r2_log_*``: R^2 of log10 over the graphs where truth and prediction are both
    positive (log undefined otherwise; a noisy low-stress Pi or a reversing shear rate can be <= 0), with
    ``n_nonpositive_*`` the number of graphs left out (reported, never hidden).
    """
    out = {}
    for k, name in enumerate(TARGET_NAMES):
        p, t = pred[:, k], true[:, k]
        out[f"r2_{name}"] = r2_score(p, t)
        out[f"mae_{name}"] = float(np.mean(np.abs(t - p)))
        nz = np.abs(t) > 1e-8
        out[f"mape_{name}"] = float(np.mean(np.abs((t[nz] - p[nz]) / t[nz]))) if nz.any() else float("nan")
        tolerance = 0.15 * np.abs(t) if name != "z_mu" else np.maximum(0.15 * np.abs(t), 0.05)
        out[f"within15_{name}"] = float(np.mean(np.abs(p - t) <= tolerance))
        if name in LOG_TARGETS:
            positive = (p > 0) & (t > 0)
            out[f"r2_log_{name}"] = (
                r2_score(np.log10(p[positive]), np.log10(t[positive])) if positive.sum() > 1 else float("nan")
            )
            out[f"n_nonpositive_{name}"] = int((~positive).sum())
    return out


def fluctuation_correlation(pred: np.ndarray, true: np.ndarray, groups: np.ndarray) -> np.ndarray:
    """Pearson correlation (per target) of predicted and true deviations from their state-point means.

    ``groups`` (G,) labels the state point (phi, sigma) of each graph; eta_r and Pi are compared in log10
    (their fluctuations are multiplicative), Z_mu linearly.  Groups with fewer than 3 graphs are skipped.
    Knowing only the stress gives 0 here: this measures whether a snapshot's own fluctuation is read.
    """
    p = np.array(pred, dtype=np.float64)
    t = np.array(true, dtype=np.float64)
    for k, name in enumerate(TARGET_NAMES):
        if name in LOG_TARGETS:
            p[:, k] = np.log10(np.clip(p[:, k], 1e-12, None))
            t[:, k] = np.log10(np.clip(t[:, k], 1e-12, None))
    dp, dt = [], []
    for g in np.unique(groups):
        m = groups == g
        if m.sum() < 3:
            continue
        dp.append(p[m] - p[m].mean(axis=0))
        dt.append(t[m] - t[m].mean(axis=0))
    if not dp:
        return np.full(len(TARGET_NAMES), np.nan)
    dp, dt = np.concatenate(dp), np.concatenate(dt)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.array([np.corrcoef(dp[:, k], dt[:, k])[0, 1] for k in range(len(TARGET_NAMES))])


def fold_metrics(pred: np.ndarray, true: np.ndarray, groups: np.ndarray, jammed=None) -> dict:
    """``regression_metrics`` plus ``fluct_*``: the within-state-point fluctuation correlation.

    ``jammed`` (G,) bool marks snapshots of shear-jammed runs: eta_r is not scored on them (it has no
    finite value), Pi and Z_mu are; ``n_jammed`` says how many there were."""
    out = regression_metrics(pred, true)
    for name, value in zip(TARGET_NAMES, fluctuation_correlation(pred, true, groups)):
        out[f"fluct_{name}"] = float(value)
    jammed = np.zeros(len(pred), dtype=bool) if jammed is None else np.asarray(jammed, dtype=bool)
    out["n_jammed"] = int(jammed.sum())
    if jammed.any():
        flowing = ~jammed
        eta = regression_metrics(pred[flowing], true[flowing]) if flowing.sum() > 1 else {}
        for key in [k for k in out if k.endswith("_eta")]:
            out[key] = eta.get(key, float("nan"))
        out["fluct_eta"] = float(fluctuation_correlation(pred[flowing], true[flowing], groups[flowing])[0])
    return out


def pressure_in_stress_units(y: torch.Tensor, stress: torch.Tensor) -> torch.Tensor:
    """Transformed targets (G, 3) with asinh(Pi / s) replaced by asinh(Pi / (s sigma)): the particle
    pressure in units of the imposed stress.  ``stress`` (G,) in sigma0."""
    out = y.clone()
    out[:, 1] = torch.asinh(torch.sinh(y[:, 1]) / stress.to(y.dtype))
    return out


def pressure_in_sigma0(y: torch.Tensor, stress: torch.Tensor) -> torch.Tensor:
    """Inverse of ``pressure_in_stress_units``."""
    out = y.clone()
    out[:, 1] = torch.asinh(torch.sinh(y[:, 1]) * stress.to(y.dtype))
    return out


STATE_TABLE_ROWS = 256  # capacity of the state-mean table (state points of the training folds)


def state_table(phi, log_stress, values, scored) -> torch.Tensor:
    """(STATE_TABLE_ROWS, 5) rows (phi, log sigma/sigma0, mean of each of 3 targets) per state point of
    training graphs: ``phi``, ``log_stress`` (G,), ``values`` (G, 3), ``scored`` (G, 3) bool (a target
    left out of a graph's mean: eta_r of an arrested packing); NaN where a state point has no scored
    value and in the unused rows."""
    key = torch.stack([phi.double(), log_stress.double()], dim=1)
    points, inverse = torch.unique(torch.round(key * 1e6) / 1e6, dim=0, return_inverse=True)
    if points.shape[0] > STATE_TABLE_ROWS:
        raise InputError(
            f"model.on_state_mean: {points.shape[0]} training state points, at most {STATE_TABLE_ROWS}"
        )
    table = torch.full((STATE_TABLE_ROWS, 5), float("nan"), dtype=torch.float64)
    table[: points.shape[0], :2] = points
    for row in range(points.shape[0]):
        members = inverse == row
        for target in range(3):
            keep = members & scored[:, target]
            if keep.any():
                table[row, 2 + target] = values[keep, target].double().mean()
    return table


def state_mean(table: torch.Tensor, phi: torch.Tensor, log_stress: torch.Tensor) -> torch.Tensor:
    """The (G, 3) state-mean of ``state_table`` at each graph's (phi, log sigma): the trained area
    fraction nearest to phi, linear in log sigma between its trained stresses (held constant beyond
    them), per target over the state points where it is known."""
    rows = table[torch.isfinite(table[:, 0])]
    if not rows.shape[0]:  # not fitted yet: zero, like target_mean before fit_target_scaling
        return torch.zeros((phi.shape[0], 3), dtype=torch.float64)
    out = torch.empty((phi.shape[0], 3), dtype=torch.float64)
    trained_phi = torch.unique(rows[:, 0])
    nearest = trained_phi[torch.argmin((phi.double().view(-1, 1) - trained_phi.view(1, -1)).abs(), dim=1)]
    for value in torch.unique(nearest):
        graphs = nearest == value
        at_phi = rows[rows[:, 0] == value]
        for target in range(3):
            known = at_phi[torch.isfinite(at_phi[:, 2 + target])]
            known = known[torch.argsort(known[:, 1])]
            x = np.interp(
                log_stress[graphs].double().numpy(), known[:, 1].numpy(), known[:, 2 + target].numpy()
            )
            out[graphs, target] = torch.from_numpy(x)
    return out


def _spread(values: torch.Tensor) -> torch.Tensor:
    """Per-column standard deviation of (G, 3) training targets, 1 for a column without spread (e.g. Z_mu
    of frictionless training runs only): dividing by ~0 would blow the loss up to inf."""
    std = values.std(dim=0)
    return torch.where(std > 1e-6, std, torch.ones_like(std))


class FoldResumePoint(L.pytorch.callbacks.ModelCheckpoint):
    """Saves a fold's whole training state after every epoch as ``<dirpath>/last.ckpt`` (weights,
    optimiser, schedule, early stopping, best so far), with torch's global random generator — the only
    one training draws from on the CPU (shuffles, dropout; numpy draws are seeded generators) — and
    whether training had decided to stop, so that a fold resumed from it ends where the uninterrupted
    fold would have (bit for bit on the CPU in one process; CUDA generators and DDP ranks' own draws are
    not carried: such a fold resumes from its last epoch, not bit for bit)."""

    def __init__(self, dirpath):
        # no monitor: the one kept checkpoint is the latest epoch's, always under the same name
        super().__init__(dirpath=dirpath, filename="last", save_top_k=1, enable_version_counter=False)
        self._trainer = None
        self._stopped = False

    def setup(self, trainer, pl_module, stage: str) -> None:
        super().setup(trainer, pl_module, stage)
        self._trainer = trainer

    def state_dict(self) -> dict:
        # saved after early stopping's verdict on the epoch (Lightning runs checkpoint callbacks last)
        stopped = bool(self._trainer is not None and self._trainer.should_stop)
        return {**super().state_dict(), "torch_random_state": torch.get_rng_state(), "stopped": stopped}

    def load_state_dict(self, state_dict: dict) -> None:
        state = dict(state_dict)
        torch.set_rng_state(state.pop("torch_random_state"))
        self._stopped = state.pop("stopped")
        super().load_state_dict(state)

    def on_train_start(self, trainer, pl_module) -> None:
        super().on_train_start(trainer, pl_module)
        if self._stopped:  # killed after training had ended (testing, saving): train no further epoch
            trainer.should_stop = True


class EpochLog(L.pytorch.callbacks.Callback):
    """One log line every ``every_n_epochs`` epochs (fold, epoch, train and validation loss, elapsed
    time): training progress that stays readable when folds train in parallel processes, where a
    progress bar per process would interleave."""

    def __init__(self, every_n_epochs: int = 10):
        if every_n_epochs < 1:
            raise InputError(f"callbacks.epoch_log.every_n_epochs={every_n_epochs}: allowed >= 1")
        self.every_n_epochs = every_n_epochs
        self.label = "training"  # train_fold names the fold
        self._start = None

    def on_train_start(self, trainer, pl_module) -> None:
        import time

        self._start = time.monotonic()

    def on_validation_epoch_end(self, trainer, pl_module) -> None:
        import time

        epoch = trainer.current_epoch + 1
        if trainer.sanity_checking or (epoch % self.every_n_epochs and epoch != trainer.max_epochs):
            return
        metrics = trainer.callback_metrics
        losses = ", ".join(
            f"{key} {float(metrics[key]):.4g}" for key in ("train/loss", "val/loss") if key in metrics
        )
        elapsed = time.monotonic() - (self._start or time.monotonic())
        log.info("%s: epoch %d/%d, %s (%.0f s)", self.label, epoch, trainer.max_epochs, losses, elapsed)


class SurrogateModule(L.LightningModule):
    """A graph network (``net``) + weighted Huber loss (``huber_beta``) over standardised targets (η_r
    masked on jammed snapshots), trained with the optimiser and learning-rate schedule given as partials
    (``optimizer``: params -> torch optimiser; ``scheduler``: (optimiser, max_epochs=) -> torch scheduler,
    stepped per epoch, or None for a constant rate), as Hydra's ``model.optimizer`` / ``model.scheduler``.

    ``net`` is Hydra's ``model.net``: a registered graph-network class with its options, given as a
    partial (``_partial_: true``; rheograph.learn.nets), whose input sizes ``node_in``, ``edge_in`` and
    ``global_in`` the training code fills in from the graph settings (rheograph.learn.train.setup_fold)
    — they follow from the data, not from a choice — and which the module builds once; or the plain
    record ``{"name", "kwargs"}`` a model file holds.  The module keeps that record as its ``net``
    hyperparameter, so that a checkpoint rebuilds the network through the registry alone (a network
    given already built could not be recorded).  ``None``: the ResGCN of the module's former defaults,
    replaced by an older checkpoint's own network when Lightning loads one (``on_load_checkpoint``).

    ``target_mean``/``target_std`` (fitted on the training fold) and the target specification
    (``targets``, rheograph.graphs.targets: each target's transform and what it is learned relative to)
    are buffers / hyperparameters, so a checkpoint alone maps graphs to physical eta_r, Pi, Z_mu.
    ``graph_inputs`` names the columns of the graph inputs u: the references of ``targets`` are found
    among them (``TargetSpec.columns``).

    With ``targets.pi.per_stress`` the network learns Pi in units of the imposed stress sigma (the graph's
    ``stress``) and the module converts back to sigma0.  Why: with k_n proportional to sigma the contact
    stress over sigma is a function of the positions (physics.md), and in sigma0 the 2.6 decades of the
    imposed stress dominate the standardised Pi target, so a snapshot's own fluctuation and a few per cent
    of bias at one state point weigh almost nothing in the loss.  Needs sigma known at prediction time
    (``log_stress`` among the graph inputs).

    With ``targets.z_mu.relative_to`` = frictional_coordination (the counted frictional coordination, a
    graph input) the network learns Z_mu minus that count: with the CLM the count is Z_mu itself, so the
    network only has to learn (close to) nothing instead of copying an input through its head.  Likewise
    ``targets.eta_r.relative_to`` (the one-solve viscosity, or the relaxed configuration's, transformed
    like the eta_r target): the network learns the correction to it, which for the
    one-solve the contact history sets (|log10 ratio| <= 0.16 with a within-state spread <= 0.08 at
    phi <= 0.78, against 1.3 decades of eta_r), so a model that meets a new area fraction extrapolates
    a small correction rather than eta_r itself.  And ``targets.pi.relative_to`` = spring_pressure (the
    contact-spring pressure per stress, on the Pi target's asinh scale; needs ``targets.pi.per_stress``):
    the network learns Pi / sigma minus it, the lubrication and dashpot parts and what the springs' sum
    misses.
    """

    def __init__(
        self,
        net=None,
        optimizer=None,
        scheduler=None,
        loss_weights=(1.0, 1.0, 1.0),
        huber_beta: float = 1.0,
        targets=None,
        graph_inputs=(),
        on_state_mean: bool = False,
        state_mean_by_stress: bool = True,
    ):
        super().__init__()
        # the network as a plain record (class name, options): what a model file holds and rebuilds
        # through the registry (rheograph.learn.nets); None: the network of the module's former defaults,
        # which on_load_checkpoint replaces by an older model file's own
        record = upgraded_hparams({})["net"] if net is None else net_record(net)
        self.targets = TargetSpec.from_config(targets)
        global_in = record["kwargs"].get("global_in") if net is not None else None  # None: not known yet
        if graph_inputs and global_in is not None and len(graph_inputs) != global_in:
            raise InputError(
                f"graph_inputs={list(graph_inputs)} names {len(graph_inputs)} columns, "
                f"model.net.global_in={global_in}"
            )
        # (target, graph-input column) of every target learned relative to an input
        self.reference_columns = self.targets.columns(graph_inputs)
        targets, graph_inputs = self.targets.to_config(), list(graph_inputs)  # hyperparameters: plain values
        # the optimiser and schedule are how a network is trained, not what it is: a checkpoint rebuilds
        # the network without them (they stay in the run's Hydra config)
        self.save_hyperparameters(ignore=["optimizer", "scheduler", "net"])
        self.hparams["net"] = record
        self.optimizer_factory = optimizer
        self.scheduler_factory = scheduler
        if optimizer is not None:
            check_training_factories(optimizer, scheduler)
        if not (math.isfinite(huber_beta) and huber_beta >= 0):
            raise InputError(f"model.huber_beta={huber_beta} is invalid: allowed >= 0 (0: L1)")
        if len(loss_weights) != 3 or min(loss_weights) < 0:
            raise InputError(f"model.loss_weights={list(loss_weights)}: three weights >= 0")
        self.net = build_net(record)
        self.register_buffer("target_mean", torch.zeros(3))
        self.register_buffer("target_std", torch.ones(3))
        # spread of the transformed targets themselves (Pi in sigma0), whatever the network learns: the
        # scale of target_loss, so that it compares models that learn in different spaces (Pi per sigma,
        # corrections to computed inputs).  Logging only, so not saved (checkpoints stay loadable).
        self.register_buffer("reference_std", torch.ones(3), persistent=False)
        self.register_buffer("loss_weights", torch.tensor(list(loss_weights), dtype=torch.float32))
        if on_state_mean:
            # the training folds' mean of each learned target per state point (fit_target_scaling):
            # the network learns the deviation of a snapshot from it
            self.register_buffer(
                "state_table", torch.full((STATE_TABLE_ROWS, 5), float("nan"), dtype=torch.float64)
            )
        self.huber = nn.SmoothL1Loss(beta=huber_beta, reduction="none")
        self._outputs = {"train": [], "val": [], "test": []}

    def on_load_checkpoint(self, checkpoint: dict) -> None:
        """A checkpoint of an earlier version (a shipped model's bundle read by Lightning's
        ``load_from_checkpoint``) states its targets and its network in the form of that version, which
        Lightning's constructor call drops: they are read from it (``upgraded_hparams``, the one
        adapter) and the network rebuilt as the checkpoint's, before its weights are loaded."""
        hparams, graph = checkpoint.get("hyper_parameters") or {}, checkpoint.get("graph")
        upgraded = upgraded_hparams(hparams, graph)
        if "targets" not in hparams and "targets" in upgraded:
            self.targets = TargetSpec.from_config(upgraded["targets"])
            self.reference_columns = self.targets.columns(upgraded["graph_inputs"])
            self.hparams.update(targets=upgraded["targets"], graph_inputs=upgraded["graph_inputs"])
        if "net" not in hparams:
            if upgraded["net"] != self.hparams["net"]:
                self.net = build_net(upgraded["net"], "checkpoint")
            self.hparams["net"] = upgraded["net"]

    def _corrected_targets(self, y: torch.Tensor, stress: torch.Tensor, u: torch.Tensor) -> torch.Tensor:
        """Transformed targets (G, 3) -> per stress and minus the computed inputs they correct."""
        out = pressure_in_stress_units(y, stress) if self.targets.pi.per_stress else y.clone()
        for target, column in self.reference_columns:
            out[:, target] = out[:, target] - u[:, column].to(out.dtype)
        return out

    def _state_key(self, stress: torch.Tensor) -> torch.Tensor:
        """log sigma of each graph for the state-mean table; 0 for a positions-only model, whose
        lookup is the per-phi mean (it is not told sigma)."""
        if self.hparams.get("state_mean_by_stress", True):
            return torch.log(stress.double())
        return torch.zeros_like(stress, dtype=torch.float64)

    def _state_mean(self, phi: torch.Tensor, stress: torch.Tensor) -> torch.Tensor | None:
        if not self.hparams.get("on_state_mean", False):
            return None
        return state_mean(self.state_table.cpu(), phi.cpu(), self._state_key(stress).cpu()).to(stress.device)

    def _learned(self, y: torch.Tensor, stress: torch.Tensor, u: torch.Tensor, phi=None) -> torch.Tensor:
        """Transformed targets (G, 3) -> the space the network learns in (before standardisation)."""
        out = self._corrected_targets(y, stress, u)
        mean = self._state_mean(phi, stress) if phi is not None else None
        return out if mean is None else out - mean.to(out.dtype)

    def fit_target_scaling(
        self, y: torch.Tensor, stress: torch.Tensor, u: torch.Tensor, phi=None, jammed=None
    ) -> None:
        """Standardisation of the learned targets, from the training graphs' transformed targets
        ``y`` (G, 3), imposed stresses ``stress`` (G,) and graph inputs ``u`` (G, global_in); with
        ``on_state_mean`` also the state-mean table, from their area fractions ``phi`` (G,) and
        ``jammed`` flags (G,) (an arrested packing's eta_r is not averaged)."""
        if self.hparams.get("on_state_mean", False):
            if phi is None or jammed is None:
                raise InputError("model.on_state_mean: fit_target_scaling needs phi and jammed")
            scored = torch.ones_like(y, dtype=torch.bool)
            scored[:, 0] = ~jammed.view(-1).bool()
            corrected = self._corrected_targets(y.double(), stress.double(), u.double())
            self.state_table.copy_(state_table(phi, self._state_key(stress), corrected, scored))
        learned = self._learned(y.double(), stress.double(), u.double(), phi)
        self.target_mean.copy_(learned.mean(dim=0))
        self.target_std.copy_(_spread(learned))
        self.reference_std.copy_(_spread(y.double()))

    def _net(self, batch) -> torch.Tensor:
        return self.net(batch.x, batch.edge_index, batch.edge_attr, batch.batch, batch.u, batch.area)

    def _transformed(self, z: torch.Tensor, batch) -> torch.Tensor:
        """Standardised network output (G, 3) -> transformed targets (Pi in sigma0)."""
        learned = z * self.target_std + self.target_mean
        mean = self._state_mean(batch.phi.view(-1), batch.stress.view(-1))
        if mean is not None:
            learned = learned + mean.to(learned.dtype)
        corrected = self.reference_columns
        if corrected:
            learned = learned.clone()
        # the corrections are in the learned space (the spring pressure per stress): added before Pi
        # returns to sigma0
        for target, column in corrected:
            learned[:, target] = learned[:, target] + batch.u[:, column].to(learned.dtype)
        if self.targets.pi.per_stress:
            learned = pressure_in_sigma0(learned, batch.stress.view(-1))
        return learned

    def forward(self, batch) -> torch.Tensor:
        """Predicted transformed targets (G, 3) (not standardised; Pi in sigma0)."""
        return self._transformed(self._net(batch), batch)

    def _step(self, batch, stage: str):
        z = self._net(batch)
        learned = self._learned(batch.y, batch.stress.view(-1), batch.u, batch.phi.view(-1))
        target = (learned - self.target_mean) / self.target_std
        # a shear-jammed run has no viscosity (its apparent eta_r diverges): its snapshots train Pi and
        # Z_mu (the loaded static packing) but never eta_r
        scored = torch.ones_like(target)
        scored[:, 0] = (~batch.jammed.view(-1)).float()
        per_target = (self.huber(z, target) * scored).sum(dim=0) / scored.sum(dim=0).clamp_min(1.0)
        loss = (per_target * self.loss_weights).sum()
        if not torch.isfinite(loss):
            raise FloatingPointError(
                f"{stage} loss is {loss.item()} (diverged): lower model.optimizer.lr or check the inputs"
            )
        size = batch.num_graphs
        self.log(
            f"{stage}/loss", loss, batch_size=size, on_epoch=True, on_step=False, prog_bar=stage == "val"
        )
        pred = self._transformed(z.detach(), batch)
        # the hyperparameter search's objective: unweighted (comparable between loss_weights) and on the
        # transformed targets in units of their training spread (comparable between what the network
        # learns: equal to the training loss's per-target sum when it learns the targets themselves)
        self.log(
            f"{stage}/target_loss",
            self.target_loss(pred, batch.y, scored),
            batch_size=size,
            on_epoch=True,
            on_step=False,
        )
        for k, name in enumerate(TARGET_NAMES):
            self.log(f"{stage}/loss_{name}", per_target[k], batch_size=size, on_epoch=True, on_step=False)
        self._outputs[stage].append((pred.cpu().numpy(), batch.y.cpu().numpy()))
        return loss

    def target_loss(self, pred: torch.Tensor, y: torch.Tensor, scored: torch.Tensor) -> torch.Tensor:
        """Sum over targets of the mean Huber loss of predicted against true transformed targets (G, 3),
        both in units of the training targets' spread; ``scored`` (G, 3) masks what is not scored."""
        per_target = self.huber(pred / self.reference_std, y / self.reference_std) * scored
        return (per_target.sum(dim=0) / scored.sum(dim=0).clamp_min(1.0)).sum()

    def training_step(self, batch, batch_idx):
        return self._step(batch, "train")

    def validation_step(self, batch, batch_idx):
        self._step(batch, "val")

    def test_step(self, batch, batch_idx):
        self._step(batch, "test")

    def _epoch_metrics(self, stage: str):
        if not self._outputs[stage]:
            return
        pred = np.concatenate([p for p, _ in self._outputs[stage]])
        true = np.concatenate([t for _, t in self._outputs[stage]])
        self._outputs[stage].clear()
        if self.trainer is not None and self.trainer.world_size > 1:
            # data-parallel: every process holds a shard; gather so that R^2 etc. cover the whole split
            # (the distributed sampler pads shards to equal length with repeated graphs)
            both = torch.from_numpy(np.concatenate([pred, true], axis=1)).to(self.device)
            gathered = self.all_gather(both).reshape(-1, 6).cpu().numpy()
            pred, true = gathered[:, :3], gathered[:, 3:]
        metrics = regression_metrics(
            physical_targets(pred, self.targets), physical_targets(true, self.targets)
        )
        self.log_dict(
            {f"{stage}/{k}": float(v) for k, v in metrics.items() if not k.startswith("n_")}, on_epoch=True
        )

    def on_train_epoch_end(self):
        self._epoch_metrics("train")

    def on_validation_epoch_end(self):
        self._epoch_metrics("val")

    def on_test_epoch_end(self):
        self._epoch_metrics("test")

    def configure_optimizers(self):
        if self.optimizer_factory is None:
            raise InputError(
                "model.optimizer is not set: a module rebuilt from a checkpoint predicts; to train it, "
                "pass optimizer=functools.partial(torch.optim.Adam, lr=...)"
            )
        optimizer = self.optimizer_factory(self.parameters())
        if self.scheduler_factory is None:
            return optimizer
        scheduler = self.scheduler_factory(optimizer, max_epochs=int(self.trainer.max_epochs))
        return {"optimizer": optimizer, "lr_scheduler": {"scheduler": scheduler, "interval": "epoch"}}
