"""The in-memory form every snapshot reader produces (``Snapshots``: configurations of one suspension at
one state point, with what the source says about them), and the geometry checks the readers apply.

Readers live beside it: ``rheograph.io.snapshots`` (any source), ``rheograph.io.hdf5`` (rheograph
trajectories) and ``rheograph.io.lfdem`` (LF_DEM runs).
"""

from __future__ import annotations

import dataclasses
import math
import zipfile
import zlib
from dataclasses import dataclass, field

import numpy as np

from rheograph.errors import InputError

# what a snapshot's physics depends on: they describe the suspension and come with the snapshot
PHYSICAL_PARAMS = ("mu", "kn_coefficient", "kt_ratio", "delta", "lub_max_gap", "critical_load", "size_ratio")
TARGET_KEYS = ("eta_r", "pressure", "z_mu")  # bare-file names of the targets η_r, Π [σ0], Z_μ
# how far (relative) a measured φ may lie from the one a source's radii give where it declares them the
# species' nominal radii (particles spread in size, unmeasured).  Radii spread by a relative p about their
# nominal values hold more area (volume) by ~p² (3p²) on average, and a draw of N of them scatters by
# ~2p/√N (3p/√N) about that: at a 10 % spread and N = 400, 0.8 ± 0.9 % in 2D (the committed polydisperse
# runs: +1.3 %), 2.3 ± 1.5 % in 3D.  A wrong unit or box edge is off by far more.
NOMINAL_PHI_TOLERANCE = 0.05
# what reading a damaged or malformed file raises: a cut or bit-flipped zip (.npz: also a flipped
# compression method or encryption flag, NotImplementedError / RuntimeError), gzip or HDF5 file (h5py:
# also RuntimeError), or values of the wrong type or shape
DAMAGED_FILE_ERRORS = (
    OSError,
    EOFError,
    zipfile.BadZipFile,
    zlib.error,
    NotImplementedError,
    RuntimeError,
    ValueError,
    KeyError,
    IndexError,
    TypeError,
)


@dataclass
class Snapshots:
    """S configurations of one N-particle system at one state point, in rheograph's units and box.

    ``positions`` (S, N, 2) [a] wrapped into the primary box, (S, N, 3) for a 3D suspension (``dim`` 3,
    cube edge ``lz`` [a]; None in 2D); ``radii`` (N,) [a], smallest 1; ``lx``, ``ly`` [a]; ``le_offset``
    (S,) [a]; ``strain`` (S,) (NaN where the source does not say); ``stress`` σ/σ0; ``phi`` area (3D:
    volume) fraction; ``params``: the physical parameters the source carries (a subset of
    ``PHYSICAL_PARAMS``); ``numerics``: the simulation step the source was made with, where known
    (``disp_max``, ``dt_max``, ``lagged_step_control``); ``targets`` (S, 3): η_r, Π [σ0], Z_μ (NaN where
    unknown); ``jammed`` (S,) bool (arrested packings, whose η_r is not a target); ``contacts``: per
    snapshot the recorded contact states (pairs, states, stretches) of a rheograph trajectory, else None;
    ``position_noise`` [a]: the stated precision of the positions, RMS per coordinate (0 for exact
    simulator output; None where a bare file or a caller does not state it); ``axial_noise`` [a]: in 3D,
    the RMS precision along the microscope's optical axis where it differs from ``position_noise``
    (confocal tracking locates particles several times less precisely in depth), which then holds the
    in-plane precision; None: the same as ``position_noise``; ``radii_nominal``: the radii are each
    particle's species' nominal radius (sizes spread about them, unmeasured) and ``phi`` the sample's
    measured fraction, which the radii give only to within ``NOMINAL_PHI_TOLERANCE``: a model reads such
    snapshots only with radii estimated from the configurations (``rheograph.graphs.radii_estimate``)."""

    source: str
    kind: str
    positions: np.ndarray
    radii: np.ndarray
    lx: float
    ly: float
    le_offset: np.ndarray
    strain: np.ndarray
    stress: float
    phi: float
    params: dict
    targets: np.ndarray
    jammed: np.ndarray
    numerics: dict = field(default_factory=dict)
    contacts: list | None = None
    position_noise: float | None = 0.0
    status: str = ""
    axial_noise: float | None = None
    lz: float | None = None
    radii_nominal: bool = False

    @property
    def n_particles(self) -> int:
        return int(self.radii.size)

    @property
    def dim(self) -> int:
        """Space dimension: 3 for spheres in a cube (``lz`` set), else 2."""
        return 2 if self.lz is None else 3

    def __len__(self) -> int:
        return int(self.positions.shape[0])

    def graph_params(self) -> dict:
        """The parameter mapping graph features and the one-solve read: physical parameters, the state
        point and N (``rheograph.graphs.features``)."""
        return {**self.params, "stress": self.stress, "phi": self.phi, "n_particles": self.n_particles}

    def select(self, index) -> Snapshots:
        """The snapshots at ``index`` (a slice, indices or a boolean mask over the S snapshots), with their
        per-snapshot values (strain, targets, arrest, recorded contacts, stated precisions) alike."""
        keep = np.arange(len(self))[index]

        def per_snapshot(value):  # a stated precision: one for all snapshots, or one each
            return value[keep] if np.ndim(value) == 1 else value

        return dataclasses.replace(
            self,
            positions=self.positions[keep],
            le_offset=self.le_offset[keep],
            strain=self.strain[keep],
            targets=self.targets[keep],
            jammed=self.jammed[keep],
            contacts=None if self.contacts is None else [self.contacts[k] for k in keep],
            position_noise=per_snapshot(self.position_noise),
            axial_noise=per_snapshot(self.axial_noise),
        )

    def missing_params(self, names=PHYSICAL_PARAMS) -> list[str]:
        return [name for name in names if name not in self.params]


def wrap_into_box(positions: np.ndarray, lx: float, ly: float, le_offset: float) -> np.ndarray:
    """Positions (N, 2) [a], anywhere, mapped into [-Lx/2, Lx/2) x [-Ly/2, Ly/2): each crossing of the
    top (bottom) boundary shifts x by -(+) le_offset, as the Lees–Edwards images do."""
    out = np.array(positions, dtype=np.float64)
    images = np.floor(out[:, 1] / ly + 0.5)
    out[:, 1] -= images * ly
    out[:, 0] -= images * le_offset
    out[:, 0] -= lx * np.floor(out[:, 0] / lx + 0.5)
    return out


def wrap_into_box3d(positions: np.ndarray, lx: float, ly: float, lz: float, le_offset: float) -> np.ndarray:
    """Positions (N, 3) [a], anywhere, mapped into the 3D box [-Lx/2, Lx/2) x [-Ly/2, Ly/2) x [-Lz/2,
    Lz/2): x and y as ``wrap_into_box`` (flow x, gradient y, the Lees–Edwards images across y), z
    (vorticity) plainly periodic."""
    out = np.array(positions, dtype=np.float64)
    out[:, :2] = wrap_into_box(out[:, :2], lx, ly, le_offset)
    out[:, 2] -= lz * np.floor(out[:, 2] / lz + 0.5)
    return out


def noisy_positions(snaps: Snapshots, k: int, eps: float, rng: np.random.Generator) -> np.ndarray:
    """Snapshot ``k``'s positions (N, 2) [a] ((N, 3) in 3D) plus Gaussian noise of ``eps`` [a] per
    coordinate drawn from ``rng``, wrapped into the box (an imaging-grade copy of it)."""
    noisy = snaps.positions[k] + rng.normal(0.0, eps, snaps.positions[k].shape)
    if snaps.lz is not None:
        return wrap_into_box3d(noisy, snaps.lx, snaps.ly, snaps.lz, snaps.le_offset[k])
    return wrap_into_box(noisy, snaps.lx, snaps.ly, snaps.le_offset[k])


def area_fraction(radii, lx: float, ly: float) -> float:
    with np.errstate(over="ignore"):  # radii of a damaged file: inf, refused by the caller's check
        return float(np.pi * np.sum(np.asarray(radii, dtype=np.float64) ** 2) / (lx * ly))


def volume_fraction(radii, lx: float, ly: float, lz: float) -> float:
    with np.errstate(over="ignore"):
        return float(4.0 * np.pi / 3.0 * np.sum(np.asarray(radii, dtype=np.float64) ** 3) / (lx * ly * lz))


def check_geometry(
    where: str,
    radii,
    lx,
    ly,
    phi,
    lz: float | None = None,
    smallest=(1.0, 1.0),
    nominal: bool = False,
    remedy: str = "",
) -> None:
    """Radii in units of the small radius, a positive box, and the stated φ equal to the one the radii
    and box give (to 1e-3: files round it); a volume fraction where the box has a third edge ``lz``.

    ``smallest``: the range the smallest radius must lie in — 1 for exactly sized species; for radii
    spread about their species' nominal size (the small species' nominal radius being a) the band the
    spread allows; None where the source defines a by its own radii (a simulation's radii file).
    ``nominal``: the radii are declared the species' nominal ones and φ measured: φ must lie within
    ``NOMINAL_PHI_TOLERANCE`` (relative) of what they give.  ``remedy``: appended to the message of a
    φ that disagrees (what the source's user can do)."""
    radii = np.asarray(radii, dtype=np.float64)
    if radii.ndim != 1 or radii.size < 2 or not np.all(np.isfinite(radii)) or radii.min() <= 0:
        raise InputError(f"{where}: radii must be (N,) positive numbers, N >= 2")
    if smallest is not None:
        low, high = smallest
        if not (low * (1 - 1e-6) <= float(radii.min()) <= high * (1 + 1e-6)):
            expected = "1" if low == high else f"between {low:g} and {high:g}"
            raise InputError(
                f"{where}: lengths must be in units of the small radius a (smallest radius {expected}, "
                f"found {radii.min():.6g}): divide positions, radii, box and le_offset by it"
            )
    if not (math.isfinite(lx) and math.isfinite(ly) and lx > 0 and ly > 0):
        raise InputError(f"{where}: box must be two positive lengths (Lx, Ly) [a], found ({lx}, {ly})")
    if lz is None:
        measured, fraction, box = area_fraction(radii, lx, ly), "an area", "(Lx, Ly)"
    else:
        if not (math.isfinite(lz) and lz > 0):
            raise InputError(f"{where}: the box's third edge lz must be a positive length [a], found {lz}")
        measured, fraction, box = volume_fraction(radii, lx, ly, lz), "a volume", "(Lx, Ly, Lz)"
    if nominal:
        if not abs(phi / measured - 1.0) <= NOMINAL_PHI_TOLERANCE:
            raise InputError(
                f"{where}: phi = {phi:g} but the nominal radii and box give {fraction} fraction "
                f"{measured:.6g}, {phi / measured - 1.0:+.1%} off, beyond the {NOMINAL_PHI_TOLERANCE:.0%} "
                f"that particles spread in size about their nominal radii make: check phi, the box {box} "
                "and the radii's units"
            )
    elif not math.isclose(measured, phi, abs_tol=1e-3):
        raise InputError(
            f"{where}: phi = {phi:g} but the radii and box give {fraction} fraction {measured:.6g}: check "
            f"the box {box} and the radii's units{remedy}"
        )


def check_configurations(where: str, positions, radii, le_offset, strain, targets, dim: int = 2) -> None:
    """Positions (S, N, dim) [a] and offsets (S,) [a] finite, with N the radii's; strain (S,) and targets
    (S, 3) finite or NaN (unknown), never infinite: what a damaged file gives otherwise."""
    n_snap = len(positions)
    if positions.ndim != 3 or positions.shape[1:] != (radii.size, dim):
        raise InputError(
            f"{where}: positions must be (S, N, {dim}) with N = {radii.size} (the radii), found "
            f"{positions.shape}"
        )
    if not np.all(np.isfinite(positions)):
        raise InputError(f"{where}: positions contain non-finite values")
    if le_offset.shape != (n_snap,) or not np.all(np.isfinite(le_offset)):
        raise InputError(f"{where}: le_offset must be ({n_snap},) finite numbers, one per snapshot")
    if strain.shape != (n_snap,) or targets.shape != (n_snap, 3):
        raise InputError(f"{where}: the strain and the targets need one value per snapshot ({n_snap})")
    if np.isinf(strain).any() or np.isinf(targets).any():
        raise InputError(f"{where}: the strain or the targets contain infinite values")


def size_ratio(radii) -> float:
    return round(float(np.max(radii) / np.min(radii)), 6)
