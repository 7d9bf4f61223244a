"""Memory a computation will need, estimated from N and the settings before anything is allocated, and
the refusal of what the machine cannot hold: one line with the estimate and the limit, instead of a run
that grows until the kernel's out-of-memory killer ends it without a word.

The limit is the least of the memory available (``MemAvailable`` of /proc/meminfo), what an address-space
limit (``ulimit -v``, RLIMIT_AS) leaves this process, and what a cgroup's memory limit (``memory.max``,
v1's ``memory.limit_in_bytes``) leaves its processes.  On a cluster node whose scheduler grants memory the
operating system does not show (or to lift the check), ``RHEOGRAPH_MEMORY_LIMIT_GB`` sets the limit
instead (``inf``: no check).

The estimates count what a computation allocates beyond the process as it stands (the imported libraries,
~170-400 MB, are already there); each is a measured cost per particle times ``MARGIN``."""

from __future__ import annotations

import math
import os
import resource
from pathlib import Path

from rheograph.errors import InputError

MEMORY_LIMIT_ENV = "RHEOGRAPH_MEMORY_LIMIT_GB"

# Measured peak resident memory beyond the imported libraries (ru_maxrss after an N = 64 warm-up, then
# Simulation(N) and 20 implicit steps at sigma/sigma0 10; CHOLMOD unless said): at phi 0.76 2.1 MB at
# N = 400, 11.5 MB at 2000 (11.2 MB with qdldl), 44.2 MB at 8000, 112.9 MB at 20 000; at phi 0.80 47.1 MB
# at N = 8000: 5.3-5.9 kB per particle.  The N = 20 000, phi 0.80 run of docs/jamming.md peaked at 483 MB
# with ~300-330 MB of libraries, ~7.5 kB per particle.  The estimate is the largest measured cost per
# particle times MARGIN (9 kB per particle: 1.5-1.7x every measurement, 1.2x the jamming run's): it covers
# what was not measured (denser packings, longer neighbour lists, allocator slack).
SIMULATION_BYTES_PER_PARTICLE = 6.0e3
# 3D (6 degrees of freedom per sphere, more neighbours than a disc): measured the same way (an N = 60
# warm-up, then Simulation3D(N) and 20 implicit steps at sigma/sigma0 10, phi 0.5, CHOLMOD): 25 MB at
# N = 500 (51 kB per particle), 140 MB at N = 2000 (70 kB per particle).  The cost per particle grows with
# N: the fill of a 3D sparse Cholesky factor grows as N^(4/3) under nested dissection, so beyond N = 2000
# the 70 kB are scaled by (N / 2000)^(1/3).
SIMULATION_BYTES_PER_PARTICLE_3D = 70.0e3
MEASURED_N_3D = 2000
# 3D by the iterative solver (solver=amg: no factor; the matrix, its multigrid hierarchy and the CG
# vectors grow as N): peaks of bench.short_run_3d less its N = 500 run's libraries (~257 MB), steady flow
# at phi 0.56: 39 kB per particle at N = 4000, 34 kB at 8000.
SIMULATION_BYTES_PER_PARTICLE_3D_ITERATIVE = 40.0e3
MARGIN = 1.5
# Graphs held by the graph builder, per particle and snapshot: GRAPH_BYTES_PER_EDGE per edge of a particle
# plus GRAPH_BYTES_PER_PARTICLE, a line just above the peaks measured at N = 2000, phi 0.76 (25 snapshots,
# edge cutoff 0.5 / 2 / 5 a: 4.6 / 9.7 / 29.6 edges per particle, 366 / 539 / 1338 bytes per particle and
# snapshot; the line gives 384 / 588 / 1384), times MARGIN.
GRAPH_BYTES_PER_EDGE = 40.0
GRAPH_BYTES_PER_PARTICLE = 200.0
# A shipped model's forward pass (hidden 64, five-model ensemble, run one after the other), per node of a
# batch: 303 MB for a batch of 25 N = 2000 graphs (6.1 kB per node; 1.2 kB per node at N = 400, where the
# allocator reused a warm-up's memory).
PREDICTION_BYTES_PER_NODE = 6.5e3
PREDICTION_BATCH = 64  # graphs per forward pass (rheograph.learn.bundle.predict_dataset's default)


def simulation_bytes(n_particles: int, dim: int = 2, iterative: bool = False) -> float:
    """Estimated peak memory [bytes] one simulation of ``n_particles`` in ``dim`` dimensions allocates
    (state, neighbour list, resistance matrix and its sparse Cholesky factor, or with ``iterative`` its
    multigrid hierarchy), beyond the libraries already loaded."""
    if dim == 3 and iterative:
        return MARGIN * SIMULATION_BYTES_PER_PARTICLE_3D_ITERATIVE * n_particles
    if dim == 3:
        fill_growth = max(1.0, n_particles / MEASURED_N_3D) ** (1.0 / 3.0)
        return MARGIN * SIMULATION_BYTES_PER_PARTICLE_3D * fill_growth * n_particles
    return MARGIN * SIMULATION_BYTES_PER_PARTICLE * n_particles


def edges_per_particle(phi: float, cutoff: float, size_ratio: float = 1.4, dim: int = 2) -> float:
    """An upper estimate of a particle's edges (surface gap < ``cutoff`` [a]) in a bidisperse packing of
    equal-area (3D: equal-volume) species at area (volume) fraction ``phi``: the particles whose centres
    lie within two mean radii plus the cut-off, less those closer than two small radii (none, without
    overlaps), plus the contacts that crowd the first shell, six in 2D and twelve in 3D (2D measured
    4.6 / 9.7 / 29.6 at phi 0.76 and cut-offs 0.5 / 2 / 5, estimated 8.5 / 14.8 / 35)."""
    phi = phi if math.isfinite(phi) else 0.9  # unknown: denser than any flowing packing
    mean_radius = (1.0 + size_ratio) / 2.0
    reach = 2.0 * mean_radius + cutoff
    if dim == 3:
        # 4 pi <a^3> / 3 with equal volumes per species: <a^3> = 2 r^3 / (1 + r^3)
        mean_volume = 4.0 * math.pi / 3.0 * 2.0 * size_ratio**3 / (1.0 + size_ratio**3)
        return 12.0 + phi / mean_volume * 4.0 * math.pi / 3.0 * max(reach**3 - 8.0, 0.0)
    mean_area = math.pi * 2.0 * size_ratio**2 / (1.0 + size_ratio**2)  # pi <a^2>, equal area per species
    return 6.0 + phi / mean_area * math.pi * max(reach**2 - 4.0, 0.0)


def graph_bytes(
    n_particles: int, n_snapshots: int, phi: float, cutoff: float, size_ratio: float, dim: int = 2
) -> float:
    """Estimated memory [bytes] of the graphs of ``n_snapshots`` snapshots of ``n_particles`` in ``dim``
    dimensions (edges and their features, node features, the builder's temporaries)."""
    per_snapshot = (
        GRAPH_BYTES_PER_EDGE * edges_per_particle(phi, cutoff, size_ratio, dim) + GRAPH_BYTES_PER_PARTICLE
    )
    return MARGIN * per_snapshot * n_particles * n_snapshots


def prediction_bytes(
    n_particles: int, n_snapshots: int, phi: float, cutoff: float, size_ratio: float, dim: int = 2
) -> float:
    """Estimated peak memory [bytes] of predicting ``n_snapshots`` snapshots of ``n_particles``: their
    graphs, one simulation's worth for the inputs computed under the simulator (the one-solve, a
    relaxation), and a forward pass over a batch of up to ``PREDICTION_BATCH`` graphs."""
    batch_nodes = min(n_snapshots, PREDICTION_BATCH) * n_particles
    return (
        graph_bytes(n_particles, n_snapshots, phi, cutoff, size_ratio, dim)
        + simulation_bytes(n_particles, dim)
        + MARGIN * PREDICTION_BYTES_PER_NODE * batch_nodes
    )


def _meminfo_available() -> float | None:
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return float(line.split()[1]) * 1024.0
    except (OSError, ValueError, IndexError):
        pass
    try:
        import psutil
    except ImportError:
        return None
    return float(psutil.virtual_memory().available)


def _address_space_left() -> float | None:
    soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    if soft == resource.RLIM_INFINITY:
        return None
    try:  # the process's present virtual size: the first field of statm, in pages
        used = int(Path("/proc/self/statm").read_text().split()[0]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, IndexError):
        used = 0
    return max(float(soft - used), 0.0)


def _read_number(path: Path) -> float | None:
    try:
        text = path.read_text().strip()
    except OSError:
        return None
    return float(text) if text.isdigit() else None  # "max" (v2's unlimited) and unreadable: no limit


def _cgroup_memory_left(membership=Path("/proc/self/cgroup"), root=Path("/sys/fs/cgroup")) -> float | None:
    """What the memory limit of this process's cgroup leaves (limit - usage), v2 or v1; None without a
    limit.  ``membership``: the process's cgroup list; ``root``: where the cgroup file system is mounted."""
    try:
        lines = Path(membership).read_text().splitlines()
    except OSError:
        return None
    root = Path(root)
    candidates = []
    for line in lines:
        hierarchy, _, controllers_path = line.partition(":")
        controllers, _, group = controllers_path.partition(":")
        group = group.lstrip("/")
        if hierarchy == "0" and controllers == "":  # v2: one unified hierarchy
            for folder in (root / group, root):
                candidates.append((folder / "memory.max", folder / "memory.current"))
        elif "memory" in controllers.split(","):  # v1: the memory controller's own hierarchy
            for folder in (root / "memory" / group, root / "memory"):
                candidates.append((folder / "memory.limit_in_bytes", folder / "memory.usage_in_bytes"))
    for limit_file, usage_file in candidates:
        limit = _read_number(limit_file)
        if limit is None or limit >= 2**60:  # v1 writes "no limit" as a number near 2^63
            continue
        usage = _read_number(usage_file) or 0.0
        return max(limit - usage, 0.0)
    return None


def memory_limit() -> tuple[float, str]:
    """(bytes this process may still allocate, what sets that limit): ``RHEOGRAPH_MEMORY_LIMIT_GB`` where
    set, else the least of the available memory, the address-space limit and the cgroup limit (inf when
    none of them is known)."""
    override = os.environ.get(MEMORY_LIMIT_ENV)
    if override is not None:
        try:
            gigabytes = float(override)
        except ValueError:
            gigabytes = math.nan
        if not gigabytes > 0:
            raise InputError(
                f"{MEMORY_LIMIT_ENV}={override!r} is invalid: a number of GB > 0 (inf: no memory check)"
            )
        return gigabytes * 1e9, f"set by {MEMORY_LIMIT_ENV}"
    limits = [
        (_meminfo_available(), "available on this machine"),
        (_address_space_left(), "left by the address-space limit (ulimit -v)"),
        (_cgroup_memory_left(), "left by the cgroup's memory limit"),
    ]
    known = [(value, source) for value, source in limits if value is not None]
    return min(known) if known else (math.inf, "no limit known")


def _gigabytes(value: float) -> str:
    return f"{value / 1e9:.3g} GB"


def check_memory(needed: float, what: str, smaller: str) -> None:
    """Refuses, with one line naming the estimate and the limit, a computation estimated to need more
    memory than the machine lets this process allocate.  ``what``: the computation (with the setting or
    file that sizes it); ``smaller``: how to ask for less."""
    limit, source = memory_limit()
    if needed > limit:
        raise InputError(
            f"{what} needs about {_gigabytes(needed)} of memory (estimated before allocating it), more than "
            f"the {_gigabytes(limit)} {source}: {smaller}, or run it where more memory is granted "
            f"({MEMORY_LIMIT_ENV}=<GB> sets the limit)"
        )


def check_simulation_memory(n_particles: int, dim: int = 2, iterative: bool = False) -> None:
    """``check_memory`` for one simulation of ``n_particles`` (``sim.n_particles``) in ``dim``
    dimensions, by a direct or (``iterative``) the multigrid solver."""
    check_memory(
        simulation_bytes(n_particles, dim, iterative),
        f"a {'3D ' if dim == 3 else ''}simulation of sim.n_particles={n_particles}",
        "lower sim.n_particles",
    )
