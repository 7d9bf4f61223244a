"""Names of state points: one run name shared by the CLI (Hydra run directories), training (simulated
missing files), flow curves and the benchmarks.  Below every other module so that none imports another
for it."""

from __future__ import annotations

from pathlib import PurePath

import numpy as np


def state_point_key(phi, stress):
    """One number per (phi, sigma/sigma0) state point, to group snapshots (scalars or arrays):
    round(phi, 6) * 1e6 + round(sigma/sigma0, 6), distinct for every sigma/sigma0 < 1e4."""
    return np.round(np.asarray(phi, dtype=np.float64), 6) * 1e6 + np.round(
        np.asarray(stress, dtype=np.float64), 6
    )


def sim_id(
    n_particles,
    phi,
    stress,
    seed,
    disp_max,
    integrator,
    lagged_step_control=False,
    dim=2,
    control="stress",
    shear_rate=None,
    radii="bidisperse",
    polydispersity=0.0,
    radii_file="",
    elastic_unloading=False,
) -> str:
    """Directory name of a state point, e.g. N400_phi0.76_s10_seed1_d0.001_euler (``_lagged`` appended
    with LF_DEM's lagged step control, ``_unloading`` with elastic unloading of sliding contacts); a 3D
    run's ends in ``_3d`` and, under rate control, names its imposed rate after the stress that scales its
    springs: N500_phi0.5_s10_rate0.1_seed1_d0.002_implicit_3d (2D as well); radii other than bidisperse
    follow: ``_poly0.05`` (``radii=polydisperse``) or ``_radii-<file stem>`` (``radii=file``), e.g.
    N400_phi0.76_s10_poly0.05_seed1_d0.002_implicit.
    """

    def text(v):  # a value that is not a number still names a directory: SimParams refuses it afterwards
        return f"{v:g}" if isinstance(v, int | float) else str(v)

    phi, stress, disp_max = (text(v) for v in (phi, stress, disp_max))
    rate = f"_rate{text(shear_rate)}" if control == "rate" else ""
    if radii == "polydisperse":
        rate += f"_poly{text(polydispersity)}"
    elif radii == "file":
        rate += f"_radii-{PurePath(str(radii_file)).stem}"
    name = f"N{n_particles}_phi{phi}_s{stress}{rate}_seed{seed}_d{disp_max}_{integrator}"
    name += "_lagged" if lagged_step_control else ""
    name += "_unloading" if elastic_unloading is True else ""
    return name + "_3d" if dim == 3 else name


def run_name(params) -> str:
    """``sim_id`` of a SimParams (the Hydra run directory of that state point)."""
    return sim_id(
        params.n_particles,
        params.phi,
        params.stress,
        params.seed,
        params.disp_max,
        params.integrator,
        params.lagged_step_control,
        params.DIM,
        params.control,
        params.shear_rate,
        params.radii,
        params.polydispersity,
        params.radii_file,
        params.elastic_unloading,
    )
