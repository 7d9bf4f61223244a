"""Parameters of a 3D state point: the 2D ``SimParams`` with a cubic box, volume fractions and a choice
of stress or rate control.

Units as in 2D: length a (small radius), force F_CL, stress sigma0 = F_CL/(6 pi a^2), time
6 pi eta0 a^2 / F_CL, shear rate gamma0_dot = F_CL / (6 pi eta0 a^2).
"""

from __future__ import annotations

from dataclasses import dataclass

from rheograph.sim.params import CONTROLS, ParameterError, SimParams

__all__ = ["CONTROLS", "DIMENSIONS", "SimParams3D", "params_from_mapping"]

DIMENSIONS = (2, 3)


@dataclass(frozen=True)
class SimParams3D(SimParams):
    """A 3D state point: N spheres, bidisperse 1 : ``size_ratio`` with equal volume of each species, in a
    cube at volume fraction ``phi``.

    ``control="stress"`` imposes sigma_xy = ``stress`` (sigma0) and solves for the shear rate each step;
    ``control="rate"`` imposes ``shear_rate`` (gamma0_dot).  The spring stiffness is scaled by ``stress``
    in both (k_n = kn_coefficient * stress / (6 pi)): under rate control ``stress`` sets only that scale,
    and should be near the stress the rate produces so that overlaps stay ~1e-2 a.
    """

    DIM = 3
    # O'Hern, Silbert, Liu & Nagel (PRE 68, 011306, 2003) find frictionless jamming of 1 : 1.4 bidisperse
    # spheres at phi_J = 0.639 (random close packing): there is no overlap-free random start above it
    PHI_MAX = 0.64
    PHI_RULE = "0 < phi <= 0.64 (random close packing of spheres)"

    dim: int = 3  # space dimension: recorded with the parameters, so that a file says what it holds
    phi: float = 0.55  # volume fraction sum(4 pi a_i^3 / 3) / (Lx Ly Lz)

    # a 3D file stores dim and both control keys (3D had them from its start) after the 2D parameters
    STORED_TAIL = ("dim", "control", "shear_rate")
    LATER_PARAMS = ("radii", "polydispersity", "radii_file")

    def validate(self) -> None:
        super().validate()
        if self.dim != 3:
            raise ParameterError(f"sim.dim={self.dim!r} is invalid for SimParams3D: allowed 3")


def params_from_mapping(mapping) -> SimParams:
    """The parameters of a ``sim`` mapping (a Hydra ``sim`` node, a file's stored params): ``SimParams3D``
    where ``dim`` is 3, else ``SimParams`` (no ``dim``, or 2: files and configs written before 3D existed
    carry none).  Raises ``ParameterError`` for another ``dim``."""
    mapping = dict(mapping)
    dim = mapping.get("dim", 2)
    if dim not in DIMENSIONS or isinstance(dim, bool):
        raise ParameterError(f"sim.dim={dim!r} is invalid: allowed one of {DIMENSIONS} (sim=3d for 3D)")
    if dim == 3:
        return SimParams3D.from_mapping(mapping)
    mapping.pop("dim", None)
    return SimParams.from_mapping(mapping)
