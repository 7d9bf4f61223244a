"""Optuna driver: a failing trial does not stop the study, a bad trial is pruned, best config written,
and a second invocation resumes the same study."""

from pathlib import Path

import optuna
import pytest
from conftest import tiny_training_overrides
from hydra import compose, initialize_config_dir

from rheograph.errors import InputError
from rheograph.learn.tune import check_study_space, make_objective, run_study

ROOT = Path(__file__).resolve().parents[1]


def test_study_survives_failures_prunes_and_resumes(tiny_files, tmp_path):
    train_overrides = [
        *tiny_training_overrides(tiny_files, tmp_path),
        "data.split=random",  # three runs in three grouped folds would train on one stress only
        "fold=[0,2]",
        "trainer.max_epochs=4",
        "~logger",
        "report=false",
        "trainer.enable_progress_bar=false",
    ]
    overrides = [
        f"output_root={tmp_path}",
        f"tune.storage=sqlite:///{tmp_path}/study.db",
        f"tune.best_experiment_dir={tmp_path}/experiment",
        "tune.n_trials=3",
        "tune.pruner.n_startup_trials=1",
        "tune.pruner.n_warmup_steps=0",
        "train_overrides=[" + ",".join(f"'{o}'" for o in train_overrides) + "]",
    ]
    with initialize_config_dir(config_dir=str(ROOT / "conf"), version_base="1.3"):
        cfg = compose(config_name="tune", overrides=overrides)
        objective = make_objective(cfg, tmp_path / "trials")

        def sometimes_failing(trial):
            if trial.number == 1:
                raise FloatingPointError("forced failure (e.g. NaN loss)")
            if trial.number == 2:
                # a trial far worse than the first from its first epoch on: the median pruner must stop
                # it through the objective's own report / should_prune path
                report = trial.report
                trial.report = lambda value, step: report(value + 1e3, step)
            return objective(trial)

        study = run_study(cfg, tmp_path / "trials", objective=sometimes_failing)
        states = [t.state for t in study.trials]
        assert len(states) == 3
        assert states.count(optuna.trial.TrialState.FAIL) == 1
        finished = [t for t in study.trials if t.state != optuna.trial.TrialState.FAIL]
        # every epoch of every trained fold is reported (steps continue over folds); a complete trial's
        # value is the mean over its two folds of the best epoch's unweighted validation loss
        complete = [t for t in finished if t.state == optuna.trial.TrialState.COMPLETE]
        assert complete and all(sorted(t.intermediate_values) == list(range(8)) for t in complete)
        for t in complete:
            values = t.intermediate_values
            per_fold = [min(values[s] for s in range(4)), min(values[s] for s in range(4, 8))]
            assert abs(t.value - sum(per_fold) / 2) < 1e-9
        pruned = [t for t in finished if t.state == optuna.trial.TrialState.PRUNED]
        assert [t.number for t in complete] == [0] and [t.number for t in pruned] == [2]
        assert sorted(pruned[0].intermediate_values) == [0]  # stopped at its first report
        best = (tmp_path / "experiment" / "resgcn_best.yaml").read_text()
        assert best.startswith("# @package _global_") and "model:" in best and "lr:" in best
        # the best experiment overrides existing keys of the training config with valid values
        from omegaconf import OmegaConf

        train = compose(config_name="train", overrides=train_overrides)
        merged = OmegaConf.merge(train, OmegaConf.load(tmp_path / "experiment" / "resgcn_best.yaml"))
        assert set(OmegaConf.to_container(merged.model)) == set(OmegaConf.to_container(train.model))
        assert len(merged.model.loss_weights) == 3 and merged.model.optimizer.lr > 0
        assert isinstance(merged.model.net.hidden, int) and isinstance(merged.data.batch_size, int)

        cfg2 = compose(
            config_name="tune", overrides=[o.replace("tune.n_trials=3", "tune.n_trials=4") for o in overrides]
        )
        study2 = run_study(cfg2, tmp_path / "trials")
        assert len(study2.trials) == 4  # resumed from the same storage, one more trial
        assert study2.trials[0].params == study.trials[0].params


def test_a_trial_whose_process_died_is_failed_and_retried(tmp_path):
    """A RUNNING trial left by a killed process (its heartbeat stopped) is marked FAIL when the study is
    resumed and retried once with the same parameters, instead of staying RUNNING for ever."""
    import time

    overrides = [
        f"output_root={tmp_path}",
        f"tune.storage=sqlite:///{tmp_path}/study.db",
        f"tune.best_experiment_dir={tmp_path}/experiment",
        "tune.n_trials=2",
        "tune.heartbeat_seconds=1",
        "tune.grace_seconds=1",
    ]
    with initialize_config_dir(config_dir=str(ROOT / "conf"), version_base="1.3"):
        cfg = compose(config_name="tune", overrides=overrides)
    storage = optuna.storages.RDBStorage(cfg.tune.storage, heartbeat_interval=1, grace_period=1)
    killed = optuna.create_study(study_name=cfg.tune.study_name, storage=storage).ask(
        {"model.optimizer.lr": optuna.distributions.FloatDistribution(1e-4, 1e-2, log=True)}
    )
    storage.record_heartbeat(killed._trial_id)  # it was running, then its process was killed
    time.sleep(2.5)
    study = run_study(
        cfg,
        tmp_path / "trials",
        objective=lambda trial: trial.suggest_float("model.optimizer.lr", 1e-4, 1e-2, log=True),
    )
    states = [t.state for t in study.trials]
    assert states[0] == optuna.trial.TrialState.FAIL  # no longer RUNNING
    retried = [t for t in study.trials if t.system_attrs.get("failed_trial") == killed.number]
    assert [t.state for t in retried] == [optuna.trial.TrialState.COMPLETE]
    assert (
        len(retried) == 1 and retried[0].params["model.optimizer.lr"] == killed.params["model.optimizer.lr"]
    )
    assert optuna.trial.TrialState.RUNNING not in states


def test_best_experiment_carries_the_tuned_values_and_the_studys_inputs(tmp_path):
    """The written experiment reproduces the best trial: its sampled values (categorical ones by their
    original type) and the study's choice of inputs (graph=paper), not the search protocol (fold)."""
    from rheograph.learn.tune import write_best_experiment

    space = {
        "model.optimizer.lr": {"type": "float", "low": 1e-4, "high": 1e-2, "log": True},
        "model.net.hidden": {"type": "categorical", "choices": [32, 64]},
        "model.loss_weights": {"type": "categorical", "choices": [[1.0, 1.0, 1.0], [2.0, 1.0, 1.0]]},
    }
    study = optuna.create_study(study_name="unit_test_search")  # no such experiment in conf/
    dists = {
        "model.optimizer.lr": optuna.distributions.FloatDistribution(1e-4, 1e-2, log=True),
        "model.net.hidden": optuna.distributions.CategoricalDistribution(["32", "64"]),
        "model.loss_weights": optuna.distributions.CategoricalDistribution(
            ["[1.0, 1.0, 1.0]", "[2.0, 1.0, 1.0]"]
        ),
    }
    for value, params in [
        (
            0.5,
            {"model.optimizer.lr": 1e-3, "model.net.hidden": "32", "model.loss_weights": "[1.0, 1.0, 1.0]"},
        ),
        (
            0.2,
            {"model.optimizer.lr": 2e-3, "model.net.hidden": "64", "model.loss_weights": "[2.0, 1.0, 1.0]"},
        ),
    ]:
        study.add_trial(optuna.trial.create_trial(params=params, distributions=dists, value=value))
    path = write_best_experiment(study, tmp_path / "experiment", ["graph=paper", "fold=0", "~logger"], space)
    with initialize_config_dir(config_dir=str(ROOT / "conf"), version_base="1.3"):
        cfg = compose(
            config_name="train",
            overrides=[f"hydra.searchpath=[file://{tmp_path}]", f"experiment={path.stem}"],
        )
        paper = compose(config_name="train", overrides=["graph=paper"])
    assert cfg.model.optimizer.lr == 2e-3 and cfg.model.net.hidden == 64
    assert list(cfg.model.loss_weights) == [2.0, 1.0, 1.0]
    assert cfg.graph.edge_features == paper.graph.edge_features  # the inputs it was tuned on
    assert cfg.fold is None and cfg.get("logger") is not None  # the search protocol is not carried


def test_the_defaults_are_queued_once_as_a_trial():
    """A study over the defaults' neighbourhood shows where the defaults stand: they are queued as one
    trial (with the values the training config holds), and only once however often the study resumes."""
    from rheograph.learn.tune import enqueue_defaults

    with initialize_config_dir(config_dir=str(ROOT / "conf"), version_base="1.3"):
        cfg = compose(config_name="tune", overrides=["hparams_search=held_out_phi076"])
        train = compose(config_name="train")
        study = optuna.create_study()
        enqueue_defaults(study, cfg)
        enqueue_defaults(study, cfg)
    (queued,) = study.get_trials(deepcopy=False)
    assert queued.state == optuna.trial.TrialState.WAITING and queued.user_attrs["defaults"]
    params = queued.system_attrs["fixed_params"]
    assert (
        params["model.optimizer.lr"] == train.model.optimizer.lr
        and params["model.net.aggr"] == train.model.net.aggr
    )
    assert params["model.loss_weights"] == str(list(train.model.loss_weights))
    assert set(params) == set(cfg.tune.search_space)


def test_epoch_reporter_prunes_by_epoch_and_names_a_metric_that_is_not_logged():
    """Steps continue over folds (first_step), the fold's best epoch is kept, the pruner's verdict ends
    the trial, and a misspelt tune.metric is one clear error, not a silent objective of inf."""
    from types import SimpleNamespace

    import torch

    from rheograph.errors import InputError
    from rheograph.learn.tune import EpochReporter

    study = optuna.create_study(pruner=optuna.pruners.ThresholdPruner(upper=1.0))
    trial = study.ask()
    reporter = EpochReporter(trial, "val/target_loss", first_step=30)
    for epoch, value in enumerate([0.5, 0.3, 0.4]):
        trainer = SimpleNamespace(
            sanity_checking=False,
            current_epoch=epoch,
            callback_metrics={"val/target_loss": torch.tensor(value)},
        )
        reporter.on_validation_epoch_end(trainer, None)
    assert reporter.best == pytest.approx(0.3)
    assert sorted(trial.storage.get_trial(trial._trial_id).intermediate_values) == [30, 31, 32]
    trainer.callback_metrics["val/target_loss"] = torch.tensor(2.0)  # above the threshold: pruned
    trainer.current_epoch = 3
    with pytest.raises(optuna.TrialPruned):
        reporter.on_validation_epoch_end(trainer, None)
    with pytest.raises(InputError, match="tune.metric='val/typo'"):
        EpochReporter(trial, "val/typo", 0).on_validation_epoch_end(trainer, None)


def test_a_study_resumed_with_another_search_space_is_refused_by_name():
    study = optuna.create_study(study_name="physics_solve_phi076")
    study.add_trial(
        optuna.trial.create_trial(
            params={"model.optimizer.lr": 1e-3, "graph.viscosity_on_solve": "True"},
            distributions={
                "model.optimizer.lr": optuna.distributions.FloatDistribution(1e-4, 1e-2, log=True),
                "graph.viscosity_on_solve": optuna.distributions.CategoricalDistribution(["False", "True"]),
            },
            value=0.1,
        )
    )
    same = {
        "model.optimizer.lr": {"type": "float"},
        "graph.viscosity_on_solve": {"type": "categorical", "choices": [False, True]},
    }
    check_study_space(study, same)  # the space its trials searched: resumed
    with pytest.raises(InputError, match="tune.study_name='physics_solve_phi076'.*graph.viscosity_on_solve"):
        check_study_space(study, {"model.optimizer.lr": {"type": "float"}})
    # one more choice: Optuna would fail every new trial; refused by name instead
    more = {**same, "graph.viscosity_on_solve": {"type": "categorical", "choices": [False, True, None]}}
    with pytest.raises(InputError, match="graph.viscosity_on_solve choices are \\['False', 'True'\\]"):
        check_study_space(study, more)


def test_sampler_seeds_are_reproducible_distinct_per_resume_and_worker_and_validated():
    from omegaconf import OmegaConf

    from rheograph.learn.tune import sampler_seed

    tune = OmegaConf.create({"sampler_seed": 0, "worker": 0})
    assert sampler_seed(tune, 0) == sampler_seed(tune, 0)
    seeds = {
        sampler_seed(tune, 0),
        sampler_seed(tune, 3),
        sampler_seed(OmegaConf.merge(tune, {"worker": 1}), 0),
    }
    assert len(seeds) == 3
    assert sampler_seed(OmegaConf.merge(tune, {"sampler_seed": None}), 5) is None
    for bad in ({"worker": -1}, {"worker": "host-a"}, {"sampler_seed": 1.5}):
        with pytest.raises(InputError, match="tune.(worker|sampler_seed)="):
            sampler_seed(OmegaConf.merge(tune, bad), 0)


def test_a_failing_trial_does_not_stop_the_study_and_the_best_is_written_then_resumed(tmp_path):
    """The driver without training (a stand-in objective over the real search space): a trial that raises
    is recorded FAIL and the study goes on, the best trial's values land in the experiment config, and a
    second invocation with a larger budget resumes the same study."""
    from omegaconf import OmegaConf

    from rheograph.learn.tune import suggest

    overrides = [
        f"output_root={tmp_path}",
        f"tune.storage=sqlite:///{tmp_path}/study.db",
        f"tune.best_experiment_dir={tmp_path}/experiment",
        "tune.n_trials=3",
    ]
    with initialize_config_dir(config_dir=str(ROOT / "conf"), version_base="1.3"):
        cfg = compose(config_name="tune", overrides=overrides)
        space = OmegaConf.to_container(cfg.tune.search_space, resolve=True)

        def objective(trial):
            values = {name: suggest(trial, name, spec) for name, spec in space.items()}
            if trial.number == 1:
                raise FloatingPointError("forced failure (e.g. NaN loss)")
            return float(values["model.optimizer.lr"])

        study = run_study(cfg, tmp_path / "trials", objective=objective)
        states = [t.state for t in study.trials]
        assert states == [
            optuna.trial.TrialState.COMPLETE,
            optuna.trial.TrialState.FAIL,
            optuna.trial.TrialState.COMPLETE,
        ]
        best = OmegaConf.load(tmp_path / "experiment" / f"{cfg.tune.study_name}_best.yaml")
        lowest = min(
            t.params["model.optimizer.lr"]
            for t in study.trials
            if t.state == optuna.trial.TrialState.COMPLETE
        )
        assert best.model.optimizer.lr == pytest.approx(lowest)

        more = compose(config_name="tune", overrides=[*overrides[:-1], "tune.n_trials=4"])
        resumed = run_study(more, tmp_path / "trials", objective=objective)
        assert len(resumed.trials) == 4  # tune.n_trials counts finished trials, failed ones included
        assert resumed.trials[0].params == study.trials[0].params
        # a resumed study draws afresh: its new trial does not replay the first invocation's first draw
        assert resumed.trials[3].params != study.trials[0].params
        # as does another worker of a shared study, from the start
        other = compose(
            config_name="tune",
            overrides=[
                *overrides[:-1],
                "tune.n_trials=1",
                "tune.worker=1",
                f"tune.storage=sqlite:///{tmp_path}/w.db",
            ],
        )
        assert (
            run_study(other, tmp_path / "trials_w1", objective=objective).trials[0].params
            != study.trials[0].params
        )
