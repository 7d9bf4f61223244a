"""Run one state point to its target strain, writing the trajectory file; resumable and interruptible.

Output cadence: a time-series row each ``output_interval`` of strain, or - when the flow stalls - each
``output_interval * jam_viscosity / stress`` of time (the time that strain interval would take at the jam
viscosity), so that a shear-jammed state still produces rows and can be recognised: a row whose apparent
viscosity sigma * dt / d(strain) exceeds ``jam_viscosity`` (or whose strain went backwards) is flagged
``jammed``.  The run ends with status "jammed" when over its last ``jam_intervals`` output intervals
(between its last ``jam_intervals`` + 1 rows) together the apparent viscosity exceeds ``jam_viscosity``
(or the strain did not advance): with the default 10 intervals, when the flow took longer than 0.1 strain
would take at the jam viscosity and did not reach it.

A 3D state point (``SimParams3D``) runs the same loop with ``Simulation3D``; under its rate control
(``control="rate"``) rows follow the strain only and no jam is detected: the imposed rate cannot stall.
"""

from __future__ import annotations

import math
import signal
import time as wallclock
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from tqdm import tqdm

from rheograph.analysis.steady import steady_extras, steady_state_summary
from rheograph.errors import hdf5_write_found_no_room
from rheograph.io.hdf5 import (
    TrajectoryFile,
    TrajectoryWriteError,
    file_is_compact,
    params_that_differ,
    read_run_info,
    rewrite,
)
from rheograph.sim import stress3d
from rheograph.sim.integrator import Simulation, particle_pressure, viscosity
from rheograph.sim.integrator3d import Simulation3D
from rheograph.sim.params import SimParams


@dataclass
class RunOutcome:
    status: str  # "completed", "jammed", "wall_limit", "interrupted", "diverged"
    strain: float
    steps: int
    wall_seconds: float
    summary: dict
    already_finished: bool = False  # read from a finished file: nothing was simulated


class _StopFlag:
    """SIGINT/SIGTERM set a flag; the loop checkpoints, the file is closed, then the signal's usual
    effect (KeyboardInterrupt / exit) follows.  A second SIGINT aborts at once."""

    def __init__(self):
        self.stop = False
        self.signum = None
        self._old = {}

    def __enter__(self):
        for sig in (signal.SIGINT, signal.SIGTERM):
            try:
                self._old[sig] = signal.signal(sig, self._handler)
            except ValueError:  # not in the main thread: leave signals alone
                pass
        return self

    def _handler(self, signum, frame):
        if self.stop and signum == signal.SIGINT:
            raise KeyboardInterrupt
        self.stop = True
        self.signum = signum

    def __exit__(self, *exc):
        for sig, old in self._old.items():
            signal.signal(sig, old)


def flow_is_jammed(d_time: float, d_strain: float, stress: float, jam_viscosity: float) -> bool:
    """Whether a flow that advanced ``d_strain`` in ``d_time`` (one row, or a window of rows together) is
    slower than ``jam_viscosity``: sigma * dt / d(strain) > jam_viscosity, or it did not advance."""
    return d_strain <= 0.0 or stress * d_time / d_strain > jam_viscosity


def first_jammed_row(time, strain, stress: float, jam_viscosity: float, jam_intervals: int) -> int | None:
    """Row of a time series at which the runner's detector ends the run as jammed (None: never);
    replays the detector on recorded series, e.g. to choose ``jam_intervals``."""
    d_time, d_strain = np.diff(time), np.diff(strain)
    for end in range(jam_intervals, d_time.size + 1):
        window = slice(end - jam_intervals, end)
        if flow_is_jammed(d_time[window].sum(), d_strain[window].sum(), stress, jam_viscosity):
            return end
    return None


def compress_at_rest(path: Path) -> None:
    """Compress a finished trajectory (rheograph.io.hdf5.COMPRESSION: raw while running, compressed at
    rest); a file already compressed is left as it is, so rerunning a finished state point changes
    nothing."""
    if not file_is_compact(path):
        rewrite(path, compressed=True)


def finished_outcome(path: Path, params: SimParams) -> RunOutcome | None:
    """The outcome of a run of these parameters that already reached ``params.strain`` (or jammed), read
    without opening the file for writing — rerunning a sweep leaves finished files byte for byte as they
    were; None when the run has to continue (or the file needs ``open_existing``'s checks and messages)."""
    try:
        info = read_run_info(path)
    except (OSError, KeyError):
        return None
    if params_that_differ(info["params"], params):
        return None
    status, strain = info["status"], info["strain"]
    if status == "jammed" or (status == "completed" and strain >= params.strain):
        return RunOutcome(status, strain, info["steps"], 0.0, info["summary"], already_finished=True)
    return None


def run_state_point(
    params: SimParams,
    path: str | Path,
    progress: bool = True,
    solver: str = "auto",
    max_steps: int | None = None,
) -> RunOutcome:
    """Simulate ``params`` into ``path`` (created, or resumed from its last checkpoint).

    ``max_steps`` stops after that many steps of this invocation (status "interrupted"; used by tests
    to emulate an interruption at a deterministic point).
    """
    path = Path(path)
    if path.exists():
        finished = finished_outcome(path, params)
        if finished is not None:
            compress_at_rest(path)  # a no-op, unless compressing failed last time (e.g. disk full)
            return finished
    traj = TrajectoryFile(path, params)
    simulation = Simulation3D if params.DIM == 3 else Simulation
    if path.exists():
        state, counters = traj.open_existing()
        sim = simulation(params, state=state, solver=solver)
    else:
        sim = simulation(params, solver=solver)
        traj.open_new(sim.state)
        counters = {}
    traj.record_solver(sim.solver.name)
    loop = _RunLoop(params, sim, traj, counters, progress, max_steps)
    write_failure = None
    try:
        with _StopFlag() as stop:
            try:
                status = loop.run(stop)
            except OSError:
                raise  # the file could not be written: recording that in it would fail too
            except Exception:
                traj.finish("error", {})  # an exception (e.g. a solver failure) is recorded, then raised
                raise
            if status != "diverged":  # never overwrite the last good checkpoint with a diverged state
                loop.save()
            summary = _summary(traj, params, status, sim.state.strain)
            summary["cpu_seconds"] = loop.cpu_seconds()
            # the run's cost in the units the scaling tables use: steps and the largest resident set
            summary["steps"] = int(sim.state.steps)
            summary["peak_memory_mb"] = loop.peak_memory_mb()
            if hasattr(sim.solver, "fallbacks"):  # an iterative solver: its solves redone exactly
                summary["solver_fallbacks"] = int(sim.solver.fallbacks)
            traj.finish(status, summary)  # partial runs get a summary too; their status says so
    except OSError as exc:
        if not hdf5_write_found_no_room(exc):
            raise  # not the trajectory's: e.g. a closed pipe on stderr
        write_failure = exc
    finally:
        loop.bar.close()
        try:
            traj.close()
        except OSError as exc:  # HDF5's last metadata did not fit either: the copy stays for the resume
            write_failure = write_failure or exc
    if write_failure is not None:
        raise TrajectoryWriteError(path, write_failure)
    if status in ("completed", "jammed"):
        compress_at_rest(path)
    if stop.signum is not None:
        # the file is checkpointed and closed; now stop the whole process (and a Hydra sweep with it)
        raise KeyboardInterrupt if stop.signum == signal.SIGINT else SystemExit(128 + stop.signum)
    return RunOutcome(status, sim.state.strain, sim.state.steps, wallclock.time() - loop.start, summary)


class _RunLoop:
    """Output cadence, snapshots, jam window and checkpoints around ``Simulation.step``."""

    def __init__(self, params, sim, traj, counters, progress, max_steps):
        self.params, self.sim, self.traj, self.max_steps = params, sim, traj, max_steps
        self.next_output = counters.get("next_output", 0.0)
        self.next_snapshot = counters.get("next_snapshot", 0.0)
        self.last_row_time = counters.get("last_row_time", -math.inf)
        self.last_row_strain = counters.get("last_row_strain", 0.0)
        # (dt, d strain) of the last jam_intervals rows: the flow counts as stalled when, over this whole
        # window, the apparent viscosity exceeds jam_viscosity (a window, so that intermittent creep near
        # DST cannot reset the detector with a single flowing interval)
        self.jam_window = [tuple(w) for w in counters.get("jam_window", [])]
        self.rate_controlled = getattr(params, "control", "stress") == "rate"
        # an imposed rate never stalls: its rows come by strain alone
        stall_time = params.output_interval * params.jam_viscosity / params.stress
        self.stall_time = math.inf if self.rate_controlled else stall_time
        self.start = wallclock.time()
        # CPU seconds of the run over all invocations, up to the last checkpoint (a killed invocation's
        # work after its last checkpoint is redone and counted once, as it is recomputed)
        self.cpu_before = float(counters.get("cpu_seconds", 0.0))
        self.cpu_start = wallclock.process_time()
        self.peak_before = float(counters.get("peak_memory_mb", 0.0))
        self.bar = tqdm(
            total=params.strain,
            initial=round(sim.state.strain, 4),
            unit="strain",
            disable=not progress,
            mininterval=1.0,
            bar_format="{l_bar}{bar}| {n:.3f}/{total:.3g} [{elapsed}<{remaining}{postfix}]",
        )

    def save(self):
        self.traj.write_checkpoint(
            self.sim.state,
            dict(
                next_output=self.next_output,
                next_snapshot=self.next_snapshot,
                last_row_time=self.last_row_time,
                last_row_strain=self.last_row_strain,
                jam_window=self.jam_window,
                cpu_seconds=self.cpu_seconds(),
                peak_memory_mb=self.peak_memory_mb(),
            ),
        )

    def peak_memory_mb(self) -> float:
        """Largest resident set of the process [MB] over all invocations of the run (Linux: ru_maxrss
        in kB; it includes what the process held before the run, e.g. an earlier run of a sweep)."""
        import resource

        return max(self.peak_before, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0)

    def cpu_seconds(self) -> float:
        return self.cpu_before + wallclock.process_time() - self.cpu_start

    def stalled(self) -> bool:
        # empty under rate control (``_row`` records no window): never stalled
        if len(self.jam_window) < self.params.jam_intervals:
            return False
        total_time = sum(w[0] for w in self.jam_window)
        total_strain = sum(w[1] for w in self.jam_window)
        return flow_is_jammed(total_time, total_strain, self.params.stress, self.params.jam_viscosity)

    def run(self, stop) -> str:
        p, s, sim = self.params, self.sim.state, self.sim
        last_checkpoint = self.start
        steps_here = 0
        while True:
            if s.strain >= p.strain:
                return "completed"
            if self.stalled():
                self._arrest_snapshot()
                return "jammed"
            if stop.stop or (self.max_steps is not None and steps_here >= self.max_steps):
                return "interrupted"
            now = wallclock.time()
            if p.max_wall_seconds and now - self.start >= p.max_wall_seconds:
                return "wall_limit"
            if now - last_checkpoint >= p.checkpoint_wall_seconds:
                self.save()
                last_checkpoint = now
            row_due = s.strain >= self.next_output or s.time - self.last_row_time >= self.stall_time
            snap_due = s.strain >= self.next_snapshot
            before = (s.time, s.strain, s.le_offset, s.positions.copy() if snap_due else None)
            result = sim.step(record=row_due or snap_due)
            steps_here += 1
            if not (math.isfinite(result.shear_rate) and np.isfinite(s.positions).all()):
                return "diverged"
            if row_due:
                self._row(result, before)
            if snap_due:
                self._snapshot(result, before)

    def _arrest_snapshot(self) -> None:
        """One snapshot of the arrested packing when the flow stops: its Π and Z_μ are what a shear-jammed
        state point is (the regular cadence, in strain, would never come round again)."""
        s = self.sim.state
        before = (s.time, s.strain, s.le_offset, s.positions.copy())
        self._snapshot(self.sim.step(record=True), before)

    def _observables(self, result):
        n = self.sim.state.radii.shape[0]
        three_d = self.params.DIM == 3
        return dict(
            shear_rate=result.shear_rate,
            viscosity=viscosity(result),
            pressure=stress3d.particle_pressure(result.stress) if three_d else particle_pressure(result),
            z_mu=2.0 * result.n_frictional / n,
            z=2.0 * result.n_contacts / n,
        )

    def _row(self, result, before):
        p = self.params
        row_time, row_strain = before[0], before[1]
        d_strain = row_strain - self.last_row_strain
        jammed = False
        if self.last_row_time > -math.inf and not self.rate_controlled:
            d_time = row_time - self.last_row_time
            jammed = flow_is_jammed(d_time, d_strain, p.stress, p.jam_viscosity)
            self.jam_window = (self.jam_window + [(d_time, d_strain)])[-p.jam_intervals :]
        obs = self._observables(result)
        if p.DIM == 3:
            obs["n1"], obs["n2"] = stress3d.normal_stress_differences(result.stress)
        self.traj.append_row(
            dict(
                time=row_time,
                strain=row_strain,
                **obs,
                max_overlap=result.max_overlap,
                max_stretch=result.max_stretch,
                dt=result.dt,
                steps=self.sim.state.steps - 1,
                jammed=jammed,
                stress=result.stress,
                stress_lubrication=result.stress_lubrication,
                stress_contact=result.stress_contact,
                stress_solvent=result.stress_solvent,
            )
        )
        self.last_row_time, self.last_row_strain = row_time, row_strain
        if row_strain >= self.next_output:
            oi = p.output_interval
            self.next_output = (math.floor(row_strain / oi + 1e-9) + 1) * oi
        self.bar.set_postfix_str(
            f"rate={obs['shear_rate']:.3g} eta_r={obs['viscosity']:.3g} Zmu={obs['z_mu']:.2f}", refresh=False
        )
        self.bar.update(min(round(self.sim.state.strain, 4), p.strain) - self.bar.n)

    def _snapshot(self, result, before):
        snap_time, snap_strain, snap_offset, positions = before
        pairs, states, stretch = result.contacts
        self.traj.append_snapshot(
            dict(
                time=snap_time,
                strain=snap_strain,
                le_offset=snap_offset,
                **self._observables(result),
                positions=positions,
                contact_pairs=pairs,
                contact_state=states,
                contact_stretch=stretch,
            )
        )
        interval = self.params.snapshot_interval
        self.next_snapshot = (math.floor(snap_strain / interval + 1e-9) + 1) * interval


def _summary(traj, params: SimParams, status: str, strain: float) -> dict:
    ts = {name: traj.h5["timeseries"][name][()] for name in traj.h5["timeseries"]}
    summary = steady_state_summary(
        ts["strain"],
        ts["time"],
        ts["pressure"],
        ts["z_mu"],
        ts["z"],
        params.stress,
        params.steady_state_strain,
        **steady_extras(params.to_dict(), ts),
    )
    summary["max_overlap"] = float(ts["max_overlap"].max()) if ts["max_overlap"].size else 0.0
    summary["jammed_fraction"] = float(ts["jammed"].mean()) if ts["jammed"].size else 0.0
    if status == "jammed":  # the apparent viscosity diverges: recorded as such, never averaged
        summary["viscosity"], summary["viscosity_se"] = math.inf, math.nan
        summary["jammed_at_strain"] = float(strain)
    return summary
