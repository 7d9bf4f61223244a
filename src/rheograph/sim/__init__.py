"""2D LF-DEM simulator (lubrication + frictional contacts, stress-controlled simple shear).

Physics kernels (``geometry``, ``lubrication``, ``contacts``, ``assembly``, ``stress``) are pure numba
functions over arrays; ``integrator.Simulation`` strings them together; I/O lives in ``rheograph.io``.
"""

from rheograph.sim.integrator import Simulation
from rheograph.sim.params import SimParams

__all__ = ["SimParams", "Simulation"]
