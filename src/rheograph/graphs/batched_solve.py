"""The resistance problems of many snapshots solved together: dense Cholesky in batches on a torch device.

A snapshot's physics inputs (its one solve, and the relaxation of the imaging models) are steps of the
simulator, each dominated by a sparse Cholesky factorisation of R_FU (``rheograph.sim.solver``): about
2 ms at N = 400 in 2D on one core, one snapshot after the other.  A GPU factorises many dense matrices
of a few thousand rows at once (``torch.linalg.cholesky_ex`` on a batch), so there the simulations of a
set of snapshots are stepped together (``rheograph.sim.integrator.step_together``): each assembles its
problem on the CPU, the batch is solved on the device, each finishes its step.  A dense factorisation
costs n^3 / 3 for n = N DOF rows against the sparse one's far smaller count, so on a CPU the sparse
solver stays faster at every N (``python -m bench.gpu --parts f`` measures both: 20x at N = 400 in 2D,
6x at N = 500 in 3D on two cores), and on a GPU the dense cost overtakes the sparse one at some N too:
beyond ``DENSE_MAX_PARTICLES`` those snapshots keep the sparse path.

Both are exact direct solvers of the same symmetric positive-definite systems: the physics inputs
differ by round-off (tests/test_batched_solve.py).
"""

from __future__ import annotations

from collections import defaultdict

import numpy as np
import torch

from rheograph.errors import InputError
from rheograph.resources import check_memory

# particles up to which a GPU solves the problems as dense matrices (3D: 12 000 rows, 1.15 GB each in
# float64).  Not yet measured on a GPU: an estimate from the sparse solver's times on one CPU core (2D
# N = 1000 8 ms, 3D N = 500 45 ms; about 16 and 380 ms at N = 2000) against a dense Cholesky of n^3 / 3
# at ~10 TFLOP/s in float64 (2D ~7 ms, 3D ~60 ms at N = 2000); part f of bench/gpu.py measures where the
# two cross
DENSE_MAX_PARTICLES = 2000
# dense matrices held at once per batch [bytes]: the matrices, their factors and the symmetrised copy
DENSE_BATCH_BYTES = 2**31
PHYSICS_SOLVERS = ("auto", "sparse", "dense")


def physics_solver_device(choice: str, device: torch.device, n_particles: int) -> torch.device | None:
    """The device on which the physics inputs' problems of snapshots of ``n_particles`` are solved as
    dense batches, or None for the sparse solver on the CPU, one snapshot after the other.  ``choice``:
    ``auto`` (dense on a CUDA ``device`` up to ``DENSE_MAX_PARTICLES``, else sparse), ``sparse`` or
    ``dense`` (on ``device``, whatever the size; what the tests compare on a CPU)."""
    if choice not in PHYSICS_SOLVERS:
        raise InputError(f"physics_solver={choice!r} is unknown: allowed {list(PHYSICS_SOLVERS)}")
    if choice == "dense":
        return device
    if choice == "auto" and device.type == "cuda" and n_particles <= DENSE_MAX_PARTICLES:
        return device
    return None


class DenseBatchSolver:
    """A ``solve_batch`` for ``step_together``: the problems of several simulations solved on ``device``
    by batched dense Cholesky, in float64, at most ``max_bytes`` of dense matrices at a time.

    A problem with nothing interacting (a diagonal drag) and one whose dense factorisation fails (not
    positive definite at round-off) are handed to the simulation's own sparse solver, which solves the
    one and reports the other as it does in a simulation."""

    def __init__(self, device: torch.device, max_bytes: int = DENSE_BATCH_BYTES):
        self.device = torch.device(device)
        self.max_bytes = int(max_bytes)

    def __call__(self, sims, problems) -> list[np.ndarray]:
        velocities: list = [None] * len(sims)
        by_rows = defaultdict(list)  # problems of equal size share a batch
        for k, (sim, lp) in enumerate(zip(sims, problems)):
            if lp.n_active:
                by_rows[sim.pattern()[2]].append(k)
            else:
                velocities[k] = sim.solve_linear(lp)
        for n_dof, members in by_rows.items():
            # the matrices, their factors and the symmetrised copy: three n^2 float64 arrays each
            per_batch = max(1, self.max_bytes // (3 * 8 * n_dof * n_dof))
            for start in range(0, len(members), per_batch):
                chunk = members[start : start + per_batch]
                solved = self._solve([sims[k] for k in chunk], [problems[k] for k in chunk], n_dof)
                for k, vel in zip(chunk, solved):
                    velocities[k] = vel
        return velocities

    def _solve(self, sims, problems, n_dof: int) -> list[np.ndarray]:
        batch = len(sims)
        what = f"the physics inputs' dense matrices ({batch} x {n_dof} rows, physics_solver=dense)"
        if self.device.type == "cpu":
            check_memory(3 * 8 * batch * n_dof * n_dof, what, "use physics_solver=sparse")
        try:
            return self._factorise_and_solve(sims, problems, n_dof)
        except torch.OutOfMemoryError:
            raise InputError(
                f"{what} do not fit on {self.device}: use physics_solver=sparse (the CPU's sparse solver)"
            ) from None

    def _factorise_and_solve(self, sims, problems, n_dof: int) -> list[np.ndarray]:
        batch = len(sims)
        dense = torch.zeros((batch, n_dof * n_dof), dtype=torch.float64, device=self.device)
        for b, (sim, lp) in enumerate(zip(sims, problems)):
            indptr, indices, _ = sim.pattern()
            # the upper triangle in CSC: entry (row, column) at row * n + column of the row-major matrix
            columns = np.repeat(np.arange(n_dof), np.diff(indptr))
            flat = torch.from_numpy(indices.astype(np.int64) * n_dof + columns).to(self.device)
            dense[b].index_put_((flat,), torch.from_numpy(lp.data).to(self.device), accumulate=True)
        upper = dense.view(batch, n_dof, n_dof)
        matrix = upper + upper.transpose(1, 2)
        matrix.diagonal(dim1=1, dim2=2).mul_(0.5)
        del dense, upper
        factor, info = torch.linalg.cholesky_ex(matrix)
        del matrix
        rhs = torch.from_numpy(np.stack([lp.rhs.T for lp in problems])).to(self.device)
        solution = torch.cholesky_solve(rhs, factor).cpu().numpy()
        failed = info.cpu().numpy()
        return [
            sim.solve_linear(lp) if failed[b] else np.ascontiguousarray(solution[b])
            for b, (sim, lp) in enumerate(zip(sims, problems))
        ]
