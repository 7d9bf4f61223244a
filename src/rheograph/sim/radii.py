"""The particle radii of a state point (``sim.radii``), in units of a, the small radius:

- ``bidisperse`` (default): N_s radii 1 then N_l radii ``size_ratio``, equal area (2D) or volume (3D) of
  the two species (``SimParams.species_counts``).
- ``polydisperse``: the same two species, each radius drawn as mean * (1 + p z) with p =
  ``polydispersity`` (0 < p <= 0.25) and z a standard normal truncated to |z| <= 2 (redrawn beyond), from
  its own stream of the seed (``numpy.random.default_rng((seed, 1))``: the positions' stream is unchanged).
- ``file``: the N radii of ``radii_file``, a ``.npy`` array or a text file of numbers (whitespace or one a
  line, ``#`` comments), in units of a (the length unit of every other parameter: k_n, the skin, the
  box), all finite, > 0, and the largest at most 10 times the smallest.

In every case the box is made from the actual radii, so that phi is exact: L^d = (sum of the particle
areas or volumes) / phi.  Lubrication (Jeffrey & Onishi's leading terms, ``size_ratio_functions``) and
contacts take each pair's own radii, so any ratio within the bound is simulated as LF_DEM does.
"""

from __future__ import annotations

import functools
import math
from pathlib import Path

import numpy as np

from rheograph.errors import ParameterError

LARGEST_RADIUS_RATIO = 10.0  # largest / smallest radius, as for size_ratio

TRUNCATION = 2.0  # drawn radii lie within mean * (1 +- TRUNCATION * polydispersity)
RADII_STREAM = 1  # the second entry of the seed sequence of the radii draw


def box_length(radii: np.ndarray, phi: float, dim: int) -> float:
    """Edge of the square (2D) or cube (3D) in which ``radii`` fill the fraction ``phi``."""
    if dim == 2:
        return math.sqrt(math.pi * float(np.sum(radii**2)) / phi)
    return (4.0 * math.pi / 3.0 * float(np.sum(radii**3)) / phi) ** (1.0 / 3.0)


def bidisperse_radii(n_small: int, n_large: int, size_ratio: float) -> np.ndarray:
    return np.concatenate([np.ones(n_small), np.full(n_large, size_ratio)])


def polydisperse_radii(
    n_small: int, n_large: int, size_ratio: float, polydispersity: float, seed: int
) -> np.ndarray:
    """Each species' radii drawn Gaussian around 1 and ``size_ratio`` with relative spread
    ``polydispersity``, truncated at ``TRUNCATION`` spreads (module docstring)."""
    rng = np.random.default_rng((seed, RADII_STREAM))
    n = n_small + n_large
    z = rng.standard_normal(n)
    while True:
        out = np.abs(z) > TRUNCATION
        if not out.any():
            break
        z[out] = rng.standard_normal(int(out.sum()))
    return bidisperse_radii(n_small, n_large, size_ratio) * (1.0 + polydispersity * z)


def read_radii_file(path: str, n_particles: int) -> np.ndarray:
    """The radii of a ``sim.radii_file``; raises ParameterError in one line naming the file."""

    def refuse(why):
        return ParameterError(f"sim.radii_file={path}: {why}")

    file = Path(path)
    try:
        if file.suffix == ".npy":
            radii = np.load(file, allow_pickle=False)
        else:
            radii = np.loadtxt(file, dtype=np.float64, ndmin=1)
    except FileNotFoundError:
        raise refuse("no such file") from None
    except (OSError, ValueError) as exc:
        why = " ".join(str(exc).split()) or type(exc).__name__
        raise refuse(f"not a list of numbers ({why})") from None
    radii = np.asarray(radii)
    if radii.dtype.kind not in "iuf" or radii.ndim != 1:
        raise refuse(f"expected one column of numbers, found an array of shape {radii.shape}")
    radii = radii.astype(np.float64)
    if radii.size != n_particles:
        raise refuse(f"{radii.size} radii, but sim.n_particles={n_particles}")
    bad = np.flatnonzero(~(np.isfinite(radii) & (radii > 0.0)))
    if bad.size:
        raise refuse(f"radius {bad[0]} is {float(radii[bad[0]])!r}: every radius must be finite and > 0")
    ratio = radii.max() / radii.min()
    if ratio > LARGEST_RADIUS_RATIO:
        raise refuse(f"largest / smallest radius {ratio:.3g} > {LARGEST_RADIUS_RATIO:g}")
    return radii


@functools.lru_cache(maxsize=16)
def _drawn(counts, size_ratio, polydispersity, seed) -> np.ndarray:
    # cached: SimParams.validate needs them, and every SimParams is validated
    radii = polydisperse_radii(*counts, size_ratio, polydispersity, seed)
    radii.flags.writeable = False
    return radii


def particle_radii(params) -> np.ndarray:
    """The (N,) radii [a] of a ``SimParams`` (module docstring); a file's are read at each call (never
    cached: it may change between the runs of one process) and checked against the box
    (``SimParams.check_box``)."""
    counts = params.species_counts()
    if params.radii == "bidisperse":
        return bidisperse_radii(*counts, params.size_ratio)
    if params.radii == "polydisperse":
        return _drawn(counts, params.size_ratio, params.polydispersity, params.seed).copy()
    radii = read_radii_file(params.radii_file, params.n_particles)
    params.check_box(float(radii.max()), box_length(radii, params.phi, params.DIM))
    return radii
