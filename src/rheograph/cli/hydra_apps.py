"""Hydra entry points; ``simulate.py``, ``train.py`` and ``tune.py`` at the repository root only call
these.  The training entry points set OMP_WAIT_POLICY before importing torch (OpenMP reads it once).
"""

from __future__ import annotations

import logging
import os
import sys
import time
from pathlib import Path

from hydra.experimental.callback import Callback
from omegaconf import DictConfig, OmegaConf

from rheograph.errors import InputError, RefusedBeforeRun, StatePointError
from rheograph.naming import run_name, sim_id

log = logging.getLogger("rheograph")


def register_resolvers() -> None:
    if not OmegaConf.has_resolver("sim_id"):
        OmegaConf.register_new_resolver("sim_id", sim_id)


# written into the run directory of a sweep's state point that could not run (StatePointError)
FAILURE_NOTE = "failed.txt"


class SweepFailures(Callback):
    """Ends a ``simulate.py -m`` sweep with the list of its state points that could not run (each has
    ``failed.txt`` in its run directory, and its log says why) and a non-zero exit status; a sweep
    without failures ends as before.  Works with every launcher: the notes are files, not return values."""

    def on_multirun_start(self, config: DictConfig, **kwargs) -> None:
        self.started = time.time()

    def on_multirun_end(self, config: DictConfig, **kwargs) -> None:
        notes = sorted(
            note
            for note in Path(config.hydra.sweep.dir).glob(f"*/{FAILURE_NOTE}")
            if note.stat().st_mtime >= self.started - 1.0  # this sweep's, not an older one's
        )
        if notes:
            lines = [f"  {note.parent}: {note.read_text().strip()}" for note in notes]
            sys.exit(
                f"simulate.py: {len(notes)} state point(s) of this sweep could not run (the others did):\n"
                + "\n".join(lines)
            )


def checked_simulate_config(cfg: DictConfig):
    """The ``SimParams`` (``SimParams3D`` for ``sim.dim=3``) of a composed ``simulate`` config, once every
    setting that can be checked without running is: the parameters, the solver backend (an unknown or
    missing one), and the memory the simulation will need.  Raises ``InputError``."""
    from rheograph.resources import check_simulation_memory
    from rheograph.sim.params3d import params_from_mapping
    from rheograph.sim.solver import resolve_solver_name

    n_particles, dim = cfg.sim.get("n_particles"), cfg.sim.get("dim", 2)
    if isinstance(n_particles, int) and dim in (2, 3):  # else the parameter check names what is wrong
        solver = resolve_solver_name(cfg.solver, 6 if dim == 3 else 3, n_particles)
        # first: checking the parameters allocates the radii
        check_simulation_memory(n_particles, dim, iterative=solver == "amg")
    params = params_from_mapping(OmegaConf.to_container(cfg.sim, resolve=True))
    params.particle_radii()  # a radii file (sim.radii=file) is read and checked here, before the run
    resolve_solver_name(cfg.solver)
    return params


# The Hydra entry points whose settings are checked before their run directory exists
RUN_SETTINGS_CHECKED = ("simulate", "tune")


def _settings_check(entry_point: str):
    """The function of the composed config that raises ``InputError`` for ``entry_point``'s rejected
    settings; chosen from fixed code, so that no configuration names code to import."""
    if entry_point == "tune":
        from rheograph.learn.tune import check_tune_settings  # lazily: optuna only for tune.py

        return check_tune_settings
    return checked_simulate_config


class CheckBeforeRunDirectory(Callback):
    """Checks a single run's settings before Hydra creates its run directory (``on_run_start``), so that
    a rejected run leaves no directory behind: ``entry_point`` is one of ``RUN_SETTINGS_CHECKED``; the
    check's ``InputError`` is printed by ``rheograph.errors.run_hydra_app`` as one line."""

    def __init__(self, entry_point: str):
        if entry_point not in RUN_SETTINGS_CHECKED:
            raise ValueError(
                f"CheckBeforeRunDirectory: entry_point {entry_point!r} is none of {RUN_SETTINGS_CHECKED}"
            )
        self.entry_point = entry_point

    def on_run_start(self, config: DictConfig, **kwargs) -> None:
        try:
            _settings_check(self.entry_point)(config)
        except InputError as exc:
            raise RefusedBeforeRun(exc) from exc


# Hydra's own files in a run directory it has just created (its configuration and the job's log)
HYDRA_RUN_FILES = (".hydra", "{job}.log")


def remove_run_directory_of_rejected_job(run_dir: Path, job_name: str) -> None:
    """Removes a sweep job's run directory that holds nothing but what Hydra wrote on creating it (a
    sweep's jobs are checked only once Hydra has made their directories): a rejected job leaves none."""
    own = {name.format(job=job_name) for name in HYDRA_RUN_FILES}
    try:
        entries = list(run_dir.iterdir())
    except OSError:
        return
    if entries and all(entry.name in own for entry in entries):
        import shutil

        shutil.rmtree(run_dir, ignore_errors=True)


def simulate_main(cfg: DictConfig) -> dict:
    """Run one state point from a composed ``simulate`` config; returns the run's summary (simulate.py
    has made the linear algebra single-threaded before anything loaded it)."""
    from hydra.core.hydra_config import HydraConfig
    from hydra.types import RunMode

    from rheograph.runs.runner import run_state_point

    try:
        params = checked_simulate_config(cfg)
    except InputError:
        if HydraConfig.initialized():
            hydra_cfg = HydraConfig.get()
            remove_run_directory_of_rejected_job(Path(hydra_cfg.runtime.output_dir), hydra_cfg.job.name)
        raise
    if params.steady_state_strain >= params.strain:  # allowed (e.g. a start-up study), but said
        log.warning(
            "sim.steady_state_strain=%g >= sim.strain=%g: no steady window, the steady averages of this "
            "run will be empty (NaN)",
            params.steady_state_strain,
            params.strain,
        )
    run_dir = Path(HydraConfig.get().runtime.output_dir) if HydraConfig.initialized() else Path.cwd()
    path = run_dir / cfg.output_file
    log.info("state point %s -> %s", run_name(params), path)
    failure_note = run_dir / FAILURE_NOTE
    failure_note.unlink(missing_ok=True)  # from an earlier sweep: this one decides afresh
    try:
        outcome = run_state_point(params, path, progress=cfg.progress, solver=cfg.solver)
    except StatePointError as exc:
        if not (HydraConfig.initialized() and HydraConfig.get().mode == RunMode.MULTIRUN):
            raise
        # one state point of a sweep: the others still run, and SweepFailures lists this one at the end
        log.error("%s: %s", run_name(params), exc)
        failure_note.write_text(f"{exc}\n")
        return {"status": "failed", "path": str(path), "reason": str(exc)}
    if outcome.already_finished:  # a rerun sweep: one line, not the summary again in every finished log
        log.info("already %s at strain %.3f: nothing to do", outcome.status, outcome.strain)
        return {"status": outcome.status, "path": str(path), **outcome.summary}
    log.info(
        "status %s after strain %.3f (%d steps, %.1f s)",
        outcome.status,
        outcome.strain,
        outcome.steps,
        outcome.wall_seconds,
    )
    for key in ("viscosity", "pressure", "z_mu", "z", "n1", "n2"):
        if key in outcome.summary:
            log.info("  steady %s = %.4g +- %.2g", key, outcome.summary[key], outcome.summary[key + "_se"])
    return {"status": outcome.status, "path": str(path), **outcome.summary}


def train_main(cfg: DictConfig) -> float:
    """Train every configured fold into the Hydra run directory; returns the mean best val/loss."""
    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
    from hydra.core.hydra_config import HydraConfig

    from rheograph.learn.train import folds_to_train, train_folds

    # Lightning's per-fold banners (GPU/TPU availability, advertising tips) drown the useful log lines
    logging.getLogger("lightning.pytorch.utilities.rank_zero").setLevel(logging.WARNING)

    run_dir = Path(HydraConfig.get().runtime.output_dir) if HydraConfig.initialized() else Path.cwd()
    summary = train_folds(cfg, run_dir)
    for key, value in sorted(summary.items()):
        log.debug("%s = %.4g", key, value)
    held_out = {
        "grouped": "held-out trajectories",
        "random": "random snapshots",
        "phi": "held-out area fractions",
    }[cfg.data.split]
    log.info(
        "test R² (%s, mean of %d fold(s)): log η_r %.3f, log Π %.3f, Z_μ %.3f | descriptor baseline "
        "%.3f, %.3f, %.3f",
        held_out,
        len(folds_to_train(cfg)),
        summary["test/r2_log_eta"],
        summary["test/r2_log_pressure"],
        summary["test/r2_z_mu"],
        summary.get("baseline/descriptors/r2_log_eta", float("nan")),
        summary.get("baseline/descriptors/r2_log_pressure", float("nan")),
        summary.get("baseline/descriptors/r2_z_mu", float("nan")),
    )
    if "baseline/descriptors_solve/r2_log_eta" in summary:
        log.info(
            "trees given the same computed inputs (one-solve η_r, counted Z_μ, spring Π): %.3f, %.3f, %.3f",
            summary["baseline/descriptors_solve/r2_log_eta"],
            summary["baseline/descriptors_solve/r2_log_pressure"],
            summary["baseline/descriptors_solve/r2_z_mu"],
        )
    if "baseline/physics_offset/r2_log_eta" in summary:
        log.info(
            "physics only, nothing learned but a (φ, σ) offset of the one-solve η_r (spring Π, counted "
            "Z_μ): %.3f, %.4f, %.4f",
            summary["baseline/physics_offset/r2_log_eta"],
            summary["baseline/physics_offset/r2_log_pressure"],
            summary["baseline/physics_offset/r2_z_mu"],
        )
    if cfg.get("report", True):
        log.info("report: %s (all metrics: metrics.json)", run_dir / "report.md")
    else:
        log.info("all metrics: %s (no report: report=false)", run_dir / "metrics.json")
    return summary["val/loss"]


def tune_main(cfg: DictConfig) -> None:
    """Run (or resume) the Optuna study of ``cfg.tune``; trials are written under the run directory."""
    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
    from hydra.core.hydra_config import HydraConfig

    from rheograph.learn.tune import run_study

    logging.getLogger("lightning.pytorch.utilities.rank_zero").setLevel(logging.WARNING)
    run_dir = Path(HydraConfig.get().runtime.output_dir) if HydraConfig.initialized() else Path.cwd()
    run_dir.mkdir(parents=True, exist_ok=True)
    run_study(cfg, run_dir)
