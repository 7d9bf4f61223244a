"""Hyperparameter search: a small driver over Optuna (>= 4) and ``hydra.compose``.

Each trial composes ``conf/train.yaml`` with the fixed ``train_overrides`` and the sampled values, then
calls :func:`rheograph.learn.train.train_folds` (the function behind ``train.py``) on the folds the
training config selects (``fold``: all, one, or a list).  The objective is the mean over those folds of
the best epoch's ``tune.metric`` (default ``val/target_loss``: the unweighted sum of the per-target
Huber losses of the transformed targets in units of their training spread, comparable between trials
whatever their ``loss_weights`` and whatever space the network learns in; with ``data.split=grouped`` a
loss on held-out trajectories).  It is reported after every epoch, so that the MedianPruner stops
hopeless trials within their first fold.  A trial that raises (diverged loss, bad sample, ...) is
recorded as FAIL and the study goes on; a trial whose process was killed is found by its missing
heartbeat, failed and retried.  The study lives in an RDB storage (SQLite by default), so a second
invocation resumes it and several workers can share one.  The best trial is written as a ready-to-use
experiment config.
"""

from __future__ import annotations

import logging
import shutil
import warnings
from pathlib import Path

import numpy as np
import optuna
from hydra import compose
from lightning.pytorch.callbacks import Callback
from omegaconf import DictConfig, OmegaConf

from rheograph.errors import InputError, hydra_error_line
from rheograph.learn.train import check_run_settings, ensure_dataset, graph_settings, setup_fold, train_folds

log = logging.getLogger("rheograph.tune")

# config groups of conf/train.yaml that describe what is learnt (a study's choice of them belongs in its
# best experiment; debug, logger and callbacks describe how it runs)
TRAIN_GROUPS = ("data", "graph", "model", "trainer")


def suggest(trial: optuna.Trial, name: str, spec: dict):
    kind = spec["type"]
    if kind == "categorical":
        # Optuna stores only scalar choices: list-valued choices (e.g. loss weights) go by their string
        labels = {str(c): c for c in spec["choices"]}
        return labels[trial.suggest_categorical(name, list(labels))]
    if kind == "int":
        return trial.suggest_int(
            name, spec["low"], spec["high"], step=spec.get("step", 1), log=spec.get("log", False)
        )
    if kind == "float":
        return trial.suggest_float(
            name, spec["low"], spec["high"], step=spec.get("step"), log=spec.get("log", False)
        )
    raise InputError(f"search space entry {name}: unknown type {kind!r} (categorical, int, float)")


def _override(name: str, value) -> str:
    if value is None:
        return f"{name}=null"
    if isinstance(value, list):
        return f"{name}=[{','.join(str(v) for v in value)}]"
    if isinstance(value, str):
        return f"{name}='{value}'"
    return f"{name}={value}"


def fixed_overrides(cfg: DictConfig) -> list[str]:
    """The study's ``train_overrides``, interpolations resolved (e.g. ``graph=${inputs}``)."""
    return [str(o) for o in OmegaConf.to_container(cfg.train_overrides, resolve=True)]


class EpochReporter(Callback):
    """Reports ``metric`` after every validation epoch of one fold to the trial (step: epochs trained
    by the trial so far, so that the pruner compares trials at equal training), keeps the fold's best,
    and ends the trial when the pruner says so."""

    def __init__(self, trial: optuna.Trial, metric: str, first_step: int):
        self.trial, self.metric, self.first_step = trial, metric, first_step
        self.best = float("inf")

    def on_validation_epoch_end(self, trainer, pl_module) -> None:
        if trainer.sanity_checking:
            return
        if self.metric not in trainer.callback_metrics:
            raise InputError(
                f"tune.metric={self.metric!r} is not logged; logged: {sorted(trainer.callback_metrics)}"
            )
        value = float(trainer.callback_metrics[self.metric])
        self.best = min(self.best, value)
        step = self.first_step + trainer.current_epoch
        self.trial.report(value, step=step)
        if self.trial.should_prune():
            raise optuna.TrialPruned(f"pruned at epoch {trainer.current_epoch}: {self.metric} = {value:.4g}")


def make_objective(cfg: DictConfig, run_root: Path):
    space = OmegaConf.to_container(cfg.tune.search_space, resolve=True)
    base = fixed_overrides(cfg)
    metric = str(cfg.tune.metric)

    def objective(trial: optuna.Trial) -> float:
        overrides = [_override(name, suggest(trial, name, spec)) for name, spec in space.items()]
        trial.set_user_attr("overrides", overrides)
        train_cfg = compose(config_name="train", overrides=base + overrides)
        epochs = int(train_cfg.trainer.max_epochs)
        reporters: list[EpochReporter] = []

        def fold_callbacks(position: int, k: int) -> list:
            reporters.append(EpochReporter(trial, metric, first_step=position * epochs))
            return [reporters[-1]]

        trial_dir = run_root / f"trial_{trial.number:04d}"
        if train_cfg.get("logger") and "save_dir" in train_cfg.logger:
            # TensorBoard per trial (folds as versions): the hparams tab shows one entry per trial and fold
            train_cfg.logger.save_dir = str(trial_dir)
        try:
            summary = train_folds(train_cfg, trial_dir, fold_callbacks)
        finally:  # a pruned, failed or killed trial is retried under a new number: its resume state is dead
            for resume_dir in trial_dir.glob("fold*_resume"):
                shutil.rmtree(resume_dir, ignore_errors=True)
        for key, value in summary.items():
            trial.set_user_attr(key, value)
        value = float(np.mean([r.best for r in reporters]))
        if not np.isfinite(value):
            raise FloatingPointError(f"trial {trial.number}: {metric} = {value}")
        return value

    return objective


def check_base_config(cfg: DictConfig) -> None:
    """Bad input in the study's fixed overrides (a glob matching nothing, an invalid data, graph, model
    or trainer option) would fail every trial; it ends the study before the first one instead, as one
    line (InputError)."""
    from hydra.errors import HydraException

    try:
        train_cfg = compose(config_name="train", overrides=fixed_overrides(cfg))
    except HydraException as exc:  # a misspelled key or option among them: named, as at train.py
        raise InputError(f"tune.train_overrides: {hydra_error_line(exc)}") from exc
    check_run_settings(train_cfg)
    ensure_dataset(train_cfg)  # debug=tiny simulates its data on first use, as under train.py
    setup_fold(train_cfg, 0, graph_settings(train_cfg))  # data, graphs and the model's own options
    for name, spec in OmegaConf.to_container(cfg.tune.search_space, resolve=True).items():
        if spec.get("type") not in ("categorical", "int", "float"):
            raise InputError(
                f"search space entry {name}: unknown type {spec.get('type')!r} (categorical, int, float)"
            )


def check_study_space(study: optuna.Study, space: dict) -> None:
    """A resumed study must search the space its finished trials searched: trials over other parameters
    (another search config writing into the same study name, e.g. held_out_phi076 with
    inputs=physics_solve next to held_out_phi076_solve) would mix incomparable trials into one study and
    its best experiment.  Refused by name instead."""
    names = set(space)
    for trial in study.get_trials(deepcopy=False, states=(optuna.trial.TrialState.COMPLETE,)):
        if set(trial.params) != names:
            raise InputError(
                f"tune.study_name={study.study_name!r}: the stored study's trials searched "
                f"{sorted(trial.params)}, this search space is {sorted(names)}; choose another "
                "tune.study_name (or tune.storage) for a different search"
            )
        # Optuna refuses other choices of a categorical parameter for every new trial (each would fail)
        for name, stored in trial.distributions.items():
            spec = space[name]
            choices = tuple(str(c) for c in spec.get("choices", ()))
            if spec["type"] == "categorical" and tuple(getattr(stored, "choices", ())) != choices:
                raise InputError(
                    f"tune.study_name={study.study_name!r}: the stored study's {name} choices are "
                    f"{list(stored.choices)}, this search space's {list(choices)}; a study keeps its "
                    "choices: choose another tune.study_name for a different search"
                )


def check_tune_settings(cfg: DictConfig) -> None:
    """The study's own numbers, checked before anything is created (the run directory, the study's
    database): ``tune.n_trials`` (the study's total, finished trials included), the heartbeat, the
    worker number and the sampler's seed.  Raises ``InputError``."""
    t = cfg.tune

    def whole(key: str, value, least: int, meaning: str) -> None:
        if not isinstance(value, int) or isinstance(value, bool) or value < least:
            raise InputError(f"tune.{key}={value!r} is invalid: an integer >= {least} ({meaning})")

    whole("n_trials", t.n_trials, 1, "the study's total number of trials, finished ones included")
    whole("heartbeat_seconds", t.heartbeat_seconds, 1, "seconds between a running trial's heartbeats")
    whole("grace_seconds", t.grace_seconds, 1, "seconds of silence after which a trial counts as dead")
    whole("worker", t.get("worker", 0), 0, "one per worker of a shared study")
    if t.sampler_seed is not None:
        whole("sampler_seed", t.sampler_seed, 0, "or null: unseeded")


def sampler_seed(tune_cfg: DictConfig, trials_so_far: int) -> int | None:
    """The TPE sampler's seed for one invocation: ``tune.sampler_seed`` for a new study (reproducible), mixed
    with the number of trials the study already holds and ``tune.worker``, so that a resumed study and
    the workers of a shared one do not replay the same random start-up configurations."""
    worker = tune_cfg.get("worker", 0)
    if not isinstance(worker, int) or worker < 0:
        raise InputError(
            f"tune.worker={worker!r} is invalid: an integer >= 0, one per worker of a shared study"
        )
    if tune_cfg.sampler_seed is None:  # unseeded: every invocation draws afresh
        return None
    if not isinstance(tune_cfg.sampler_seed, int) or tune_cfg.sampler_seed < 0:
        raise InputError(f"tune.sampler_seed={tune_cfg.sampler_seed!r} is invalid: an integer >= 0, or null")
    words = [tune_cfg.sampler_seed, int(trials_so_far), worker]
    return int(np.random.SeedSequence(words).generate_state(1)[0])


def run_study(cfg: DictConfig, run_root: Path, objective=None) -> optuna.Study:
    check_tune_settings(cfg)
    t = cfg.tune
    # heartbeats: a trial whose process died (a killed session, a lost node) stops heartbeating and is
    # marked FAIL when the study next runs, then retried once with the same parameters; without them
    # it would stay RUNNING for ever
    with warnings.catch_warnings():  # the retry callback is marked experimental (stable since 2.8)
        warnings.simplefilter("ignore", optuna.exceptions.ExperimentalWarning)
        try:
            storage = optuna.storages.RDBStorage(
                t.storage,
                heartbeat_interval=int(t.heartbeat_seconds),
                grace_period=int(t.grace_seconds),
                heartbeat_stale_trial_callback=optuna.storages.RetryHeartbeatStaleTrialCallback(max_retry=1),
            )
        except Exception as exc:  # SQLAlchemy: an unknown dialect, a malformed URL, an unreachable server
            raise InputError(
                f"tune.storage={t.storage!r} is not a usable database URL ({type(exc).__name__}: "
                f"{str(exc).splitlines()[0]}); e.g. sqlite:///outputs/tune/study.db"
            ) from exc
    if objective is None:  # after the storage: a bad URL is named before any data is read
        check_base_config(cfg)
    study = optuna.create_study(
        study_name=t.study_name,
        storage=storage,
        load_if_exists=True,
        direction=t.direction,
        pruner=optuna.pruners.MedianPruner(
            n_startup_trials=t.pruner.n_startup_trials, n_warmup_steps=t.pruner.n_warmup_steps
        ),
    )
    study.sampler = optuna.samplers.TPESampler(seed=sampler_seed(t, len(study.trials)))
    check_study_space(study, OmegaConf.to_container(t.search_space, resolve=True))
    if t.get("enqueue_defaults") and objective is None:
        enqueue_defaults(study, cfg)
    done = sum(s.state.is_finished() for s in study.trials)
    remaining = max(0, t.n_trials - done)  # a study resumed with a lower n_trials runs no more
    log.info("study %s in %s: %d trials finished, %d to run", t.study_name, t.storage, done, remaining)
    study.optimize(
        objective or make_objective(cfg, run_root),
        n_trials=remaining,
        catch=(Exception,),
        gc_after_trial=True,
    )
    states = {s: sum(tr.state == s for tr in study.trials) for s in optuna.trial.TrialState}
    log.info("trials: %s", {s.name: n for s, n in states.items() if n})
    if any(tr.state == optuna.trial.TrialState.COMPLETE for tr in study.trials):
        space = OmegaConf.to_container(t.search_space, resolve=True)
        path = write_best_experiment(study, Path(t.best_experiment_dir), fixed_overrides(cfg), space)
        log.info("best trial %d: %s = %.4g -> %s", study.best_trial.number, t.metric, study.best_value, path)
    return study


def default_params(cfg: DictConfig) -> dict:
    """The training config's own values (with the study's fixed overrides) of the searched parameters,
    as Optuna stores them (categorical choices by their string)."""
    train_cfg = compose(config_name="train", overrides=fixed_overrides(cfg))
    params = {}
    for name, spec in OmegaConf.to_container(cfg.tune.search_space, resolve=True).items():
        value = OmegaConf.select(train_cfg, name)
        value = OmegaConf.to_container(value) if OmegaConf.is_config(value) else value
        if spec["type"] == "categorical":
            if value not in spec["choices"]:
                log.info("default %s = %s is not among the choices: defaults not queued", name, value)
                return {}
            value = str(value)
        elif not spec["low"] <= value <= spec["high"]:
            log.info("default %s = %s is outside the range: defaults not queued", name, value)
            return {}
        params[name] = value
    return params


def enqueue_defaults(study: optuna.Study, cfg: DictConfig) -> None:
    """Queue the current defaults as a trial (once per study), so that the study shows where they
    stand among the sampled configurations."""
    params = default_params(cfg)
    # a queued trial holds its values as fixed_params until it runs
    seen = [t.system_attrs.get("fixed_params", t.params) for t in study.get_trials(deepcopy=False)]
    if params and params not in seen:
        study.enqueue_trial(params, user_attrs={"defaults": True})
        log.info("defaults queued as a trial: %s", params)


def write_best_experiment(
    study: optuna.Study, directory: Path, base_overrides: list[str], space: dict
) -> Path:
    """``conf/experiment/<study>_best.yaml``: use with ``python train.py experiment=<study>_best``.

    It holds the best trial's sampled values and the config-group choices among the study's fixed
    overrides (e.g. ``graph=paper``: the inputs the values were tuned for); the other fixed overrides
    (folds, epochs, threads: the search's protocol) stay in a comment."""
    directory.mkdir(parents=True, exist_ok=True)
    best = study.best_trial
    groups = [o.split("=", 1) for o in base_overrides if "=" in o and not o.startswith(("~", "+"))]
    groups = [(k, v) for k, v in groups if k in TRAIN_GROUPS]
    lines = [
        "# @package _global_",
        f"# best trial {best.number} of Optuna study '{study.study_name}': objective {best.value:.6g}",
        f"# fixed overrides of the study: {base_overrides}",
    ]
    if groups:
        lines += ["defaults:"] + [f"  - override /{k}: {v}" for k, v in groups]
    nested: dict = {}
    for name, value in best.params.items():
        node = nested
        *parents, leaf = name.split(".")
        for p in parents:
            node = node.setdefault(p, {})
        spec = space[name]
        if spec["type"] == "categorical":  # stored by the choice's string (see ``suggest``)
            value = {str(c): c for c in spec["choices"]}[value]
        node[leaf] = value
    text = "\n".join(lines) + "\n" + OmegaConf.to_yaml(OmegaConf.create(nested))
    path = directory / f"{study.study_name}_best.yaml"
    path.write_text(text)
    return path
