"""Run one state point to its target strain, writing the trajectory file; resumable and interruptible.

Output cadence: a time-series row each ``output_interval`` of strain, or - when the flow stalls - each
``output_interval * jam_viscosity / stress`` of time (the time that strain interval would take at the jam
viscosity), so that a shear-jammed state still produces rows and can be recognised: a row whose apparent
viscosity sigma * dt / d(strain) exceeds ``jam_viscosity`` (or whose strain went backwards) is flagged
``jammed``; ``jam_intervals`` consecutive flagged rows end the run with status "jammed".
"""

from __future__ import annotations

import math
import signal
import time as wallclock
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from tqdm import tqdm

from rheograph.analysis import steady_state_summary
from rheograph.io.hdf5 import TrajectoryFile
from rheograph.sim.integrator import Simulation, particle_pressure, viscosity
from rheograph.sim.params import SimParams


@dataclass
class RunOutcome:
    status: str  # "completed", "jammed", "wall_limit", "interrupted", "diverged"
    strain: float
    steps: int
    wall_seconds: float
    summary: dict


class _StopFlag:
    """SIGINT/SIGTERM set a flag; the loop checkpoints and returns (a second SIGINT aborts)."""

    def __init__(self):
        self.stop = False
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

    def __exit__(self, *exc):
        for sig, old in self._old.items():
            signal.signal(sig, old)


def run_state_point(
    params: SimParams,
    path: str | Path,
    progress: bool = True,
    solver: str = "qdldl",
    max_steps: int | None = None,
) -> RunOutcome:
    """Simulate ``params`` into ``path`` (created, or resumed from its last checkpoint).

    ``max_steps`` stops after that many steps of this invocation (status "interrupted"; used by tests
    to emulate an interruption at a deterministic point).
    """
    path = Path(path)
    traj = TrajectoryFile(path, params)
    if path.exists():
        state, counters = traj.open_existing()
        sim = Simulation(params, state=state, solver=solver)
    else:
        sim = Simulation(params, solver=solver)
        traj.open_new(sim.state)
        counters = {}
    s = sim.state
    n = s.radii.shape[0]
    oi = params.output_interval
    next_output = counters.get("next_output", 0.0)
    next_snapshot = counters.get("next_snapshot", 0.0)
    last_row_time = counters.get("last_row_time", -math.inf)
    last_row_strain = counters.get("last_row_strain", 0.0)
    jam_run = counters.get("jam_run", 0)
    stall_time = oi * params.jam_viscosity / params.stress
    status = "running"
    start = wallclock.time()
    last_checkpoint = start
    steps_here = 0

    def save():
        traj.write_checkpoint(
            s,
            dict(
                next_output=next_output,
                next_snapshot=next_snapshot,
                last_row_time=last_row_time,
                last_row_strain=last_row_strain,
                jam_run=jam_run,
            ),
        )

    bar = tqdm(
        total=params.strain,
        initial=round(s.strain, 4),
        unit="strain",
        disable=not progress,
        mininterval=1.0,
        bar_format="{l_bar}{bar}| {n:.3f}/{total:.3g} [{elapsed}<{remaining}{postfix}]",
    )
    try:
        with _StopFlag() as stop:
            while True:
                if s.strain >= params.strain:
                    status = "completed"
                    break
                if jam_run >= params.jam_intervals:
                    status = "jammed"
                    break
                if stop.stop:
                    status = "interrupted"
                    break
                if max_steps is not None and steps_here >= max_steps:
                    status = "interrupted"
                    break
                now = wallclock.time()
                if params.max_wall_seconds and now - start >= params.max_wall_seconds:
                    status = "wall_limit"
                    break
                if now - last_checkpoint >= params.checkpoint_wall_seconds:
                    save()
                    last_checkpoint = now
                row_due = s.strain >= next_output or s.time - last_row_time >= stall_time
                snap_due = s.strain >= next_snapshot
                if snap_due:
                    snap_positions = s.positions.copy()
                    snap_time, snap_strain, snap_offset = s.time, s.strain, s.le_offset
                row_time, row_strain = s.time, s.strain
                result = sim.step(record=row_due or snap_due)
                steps_here += 1
                if not (math.isfinite(result.shear_rate) and np.isfinite(s.positions).all()):
                    status = "diverged"
                    break
                if row_due or snap_due:
                    eta = viscosity(result)
                    pressure = particle_pressure(result)
                    z_mu = 2.0 * result.n_frictional / n
                    z = 2.0 * result.n_contacts / n
                if row_due:
                    d_strain = row_strain - last_row_strain
                    jammed = last_row_time > -math.inf and (
                        d_strain <= 0.0
                        or params.stress * (row_time - last_row_time) / d_strain > params.jam_viscosity
                    )
                    jam_run = jam_run + 1 if jammed else 0
                    traj.append_row(
                        dict(
                            time=row_time,
                            strain=row_strain,
                            shear_rate=result.shear_rate,
                            viscosity=eta,
                            pressure=pressure,
                            z_mu=z_mu,
                            z=z,
                            max_overlap=result.max_overlap,
                            max_stretch=result.max_stretch,
                            dt=result.dt,
                            steps=s.steps - 1,
                            jammed=jammed,
                            stress=result.stress,
                            stress_lubrication=result.stress_lubrication,
                            stress_contact=result.stress_contact,
                            stress_solvent=result.stress_solvent,
                        )
                    )
                    last_row_time, last_row_strain = row_time, row_strain
                    if row_strain >= next_output:
                        next_output = (math.floor(row_strain / oi + 1e-9) + 1) * oi
                    bar.set_postfix_str(
                        f"rate={result.shear_rate:.3g} eta_r={eta:.3g} Zmu={z_mu:.2f}", refresh=False
                    )
                    bar.update(min(round(s.strain, 4), params.strain) - bar.n)
                if snap_due:
                    pairs, states, stretch = result.contacts
                    traj.append_snapshot(
                        dict(
                            time=snap_time,
                            strain=snap_strain,
                            le_offset=snap_offset,
                            shear_rate=result.shear_rate,
                            viscosity=eta,
                            pressure=pressure,
                            z_mu=z_mu,
                            z=z,
                            positions=snap_positions,
                            contact_pairs=pairs,
                            contact_state=states,
                            contact_stretch=stretch,
                        )
                    )
                    next_snapshot = (math.floor(snap_strain / params.snapshot_interval + 1e-9) + 1) * (
                        params.snapshot_interval
                    )
        save()
        ts = {name: traj.h5["timeseries"][name][()] for name in traj.h5["timeseries"]}
        summary = steady_state_summary(
            ts["strain"],
            ts["time"],
            ts["pressure"],
            ts["z_mu"],
            ts["z"],
            params.stress,
            params.steady_state_strain,
        )
        summary["max_overlap"] = float(ts["max_overlap"].max()) if ts["max_overlap"].size else 0.0
        summary["jammed_fraction"] = float(ts["jammed"].mean()) if ts["jammed"].size else 0.0
        if status in ("completed", "jammed", "diverged"):
            traj.finish(status, summary)
        else:
            traj.finish(status, {})
    finally:
        bar.close()
        traj.close()
    return RunOutcome(status, s.strain, s.steps, wallclock.time() - start, summary)
