"""Simulation parameters with validation.  The physical defaults are physics.md's (LF_DEM's CLM 2D set-up);
the numerical ones (explicit Euler at disp_max 1e-3, a snapshot every 0.5 strain) are LF_DEM's, which
files written without them resume with.  The command line's default preset ``sim=n400`` (``conf/sim/``)
selects the converged numerics: ``integrator="implicit"``, ``disp_max=2e-3``, ``snapshot_interval=0.1``."""

from __future__ import annotations

import dataclasses
import math
import numbers
from dataclasses import dataclass

from rheograph.errors import ParameterError
from rheograph.sim.radii import box_length, particle_radii

INTEGRATORS = ("euler", "implicit")
CONTROLS = ("stress", "rate")
RADII = ("bidisperse", "polydisperse", "file")
POLYDISPERSITY_MAX = 0.25  # relative spread of sim.radii=polydisperse; radii truncated at 2 spreads
LAGGED_SUFFIX = "-lagged"  # scheme label of LF_DEM's lagged step control


def scheme_name(integrator: str, lagged_step_control: bool) -> str:
    """Label of a time-stepping scheme, e.g. "implicit" or "euler-lagged" (LF_DEM's discretisation)."""
    return integrator + (LAGGED_SUFFIX if lagged_step_control else "")


def scheme_settings(name: str) -> dict:
    """The SimParams fields of a scheme label (inverse of ``scheme_name``)."""
    lagged = name.endswith(LAGGED_SUFFIX)
    return {"integrator": name.removesuffix(LAGGED_SUFFIX), "lagged_step_control": lagged}


@dataclass(frozen=True)
class SimParams:
    """All physical and numerical parameters of one state point (numerical defaults: LF_DEM's explicit
    scheme; pass ``integrator="implicit", disp_max=2e-3`` for the converged numerics of ``sim=n400``).

    Units: length a (small radius), force F_CL, stress sigma0 = F_CL/(6 pi a^2), time 6 pi eta0 a^2 / F_CL.
    """

    # plain class attributes (not fields): what a 3D subclass (``params3d.SimParams3D``) changes
    DIM = 2  # space dimension: the box is a square, phi an area fraction
    PHI_RULE = "0 < phi <= 0.86"
    PHI_MAX = 0.86  # ~ random close packing of this bidisperse mixture: no overlap-free start above

    n_particles: int = 400  # total particle count N (bidisperse, equal area of each species)
    phi: float = 0.76  # area fraction sum(pi a_i^2) / (Lx Ly)
    stress: float = 10.0  # imposed shear stress sigma / sigma0
    seed: int = 1  # RNG seed of the initial configuration
    strain: float = 5.0  # total strain to run
    size_ratio: float = 1.4  # large / small radius
    mu: float = 0.5  # friction coefficient (CLM), 0 for frictionless
    critical_load: float = 1.0  # F_CL, the unit of force: always 1 (kept explicit for the CLM's formulas)
    lub_max_gap: float = 0.5  # lubrication cut-off, reduced gap h / a_bar
    delta: float = 1e-3  # lubrication regularisation (h_min / a_bar)
    kn_coefficient: float = 2e4  # k_n = kn_coefficient * (sigma/sigma0) / (6 pi)  [F_CL / a^2]
    kt_ratio: float = 0.5  # k_t / k_n
    disp_max: float = 1e-3  # max displacement per step [a]
    integrator: str = "euler"  # "euler" (explicit, LF_DEM) or "implicit" (linearly implicit springs)
    lagged_step_control: bool = False  # bound dt with the previous step's pair speeds, as LF_DEM does
    dt_max: float = 1.0  # cap on dt when all velocities vanish [6 pi eta0 a^2 / F_CL]
    neighbour_skin: float = 0.4  # Verlet skin [a]; the matrix pattern lives as long as the list
    output_interval: float = 0.01  # strain between time-series rows
    snapshot_interval: float = 0.5  # strain between configuration snapshots
    steady_state_strain: float = 1.0  # strain after which averages are taken
    jam_viscosity: float = 1e5  # apparent viscosity above which an output interval counts as jammed
    jam_intervals: int = 10  # output intervals over which a jam_viscosity-slow flow ends the run as jammed
    max_wall_seconds: float = 0.0  # wall-clock budget of one invocation (0: unlimited); resumable
    checkpoint_wall_seconds: float = 60.0  # wall seconds between checkpoints
    relax_tolerance: float = 1e-4  # max overlap [a] accepted for the initial configuration
    initial_min_gap: float = 0.01  # radii inflated by (1 + this) while relaxing, so gaps start open
    # added after files were written without them: stored only off their defaults (``stored_dict``)
    control: str = "stress"  # "stress" (imposed sigma_xy = stress) or "rate" (imposed shear_rate)
    shear_rate: float = 1.0  # imposed shear rate under rate control [gamma0_dot]; unused under stress
    radii: str = "bidisperse"  # "bidisperse" (1 : size_ratio), "polydisperse" or "file" (radii_file)
    polydispersity: float = 0.0  # relative Gaussian spread of each species' radii (radii=polydisperse)
    radii_file: str = ""  # text or .npy file of the N radii [a] (radii=file)
    elastic_unloading: bool = False  # a sliding contact whose sliding reverses sticks (implicit only)

    # the parameters above in the order a file stores them, and those stored only off their defaults:
    # a 2D stress-controlled bidisperse run stores exactly what it stored before they existed
    STORED_TAIL = ()
    LATER_PARAMS = ("control", "shear_rate", "radii", "polydispersity", "radii_file", "elastic_unloading")

    def __post_init__(self) -> None:
        self.validate()

    # ---- derived quantities -------------------------------------------------------------------
    @property
    def kn(self) -> float:
        return self.kn_coefficient * self.stress / (6.0 * math.pi)

    @property
    def kt(self) -> float:
        return self.kt_ratio * self.kn

    def species_counts(self) -> tuple[int, int]:
        """(n_small, n_large) with equal area of each species: n_s = size_ratio^2 n_l (the species of
        ``radii="bidisperse"`` and ``"polydisperse"``)."""
        n_large = round(self.n_particles / (1.0 + self.size_ratio**self.DIM))
        return self.n_particles - n_large, n_large

    def particle_radii(self):
        """The N radii [a] of this state point (``rheograph.sim.radii``): bidisperse, drawn, or read."""
        return particle_radii(self)

    def box_length(self) -> float:
        """Edge of the square (2D) or cubic (3D) box [a] that holds the radii at fraction ``phi``."""
        if self.radii == "bidisperse":  # the closed form: the box of every run written before radii
            n_small, n_large = self.species_counts()
            if self.DIM == 2:
                return math.sqrt(math.pi * (n_small + n_large * self.size_ratio**2) / self.phi)
            volume = 4.0 * math.pi / 3.0 * (n_small + n_large * self.size_ratio**3)
            return (volume / self.phi) ** (1.0 / 3.0)
        return box_length(self.particle_radii(), self.phi, self.DIM)

    def check_box(self, largest_radius: float, box_length: float) -> None:
        """Raises ParameterError when the box is too small for the interaction cut-off of two particles
        of the largest radius: the minimum image must be unique for the longest interaction."""
        cutoff = 2.0 * largest_radius * (1.0 + 0.5 * self.lub_max_gap) + self.neighbour_skin
        if box_length < 2.0 * cutoff:
            n_min = math.ceil(self.n_particles * (2.0 * cutoff / box_length) ** self.DIM)
            raise ParameterError(
                f"sim.n_particles={self.n_particles} is too small for the interaction cut-off at "
                f"phi={self.phi}: the box (L={box_length:.2f}) must be at least twice the cut-off "
                f"({cutoff:.2f}); use n_particles >= {n_min}"
            )

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    def stored_dict(self) -> dict:
        """The parameters as a trajectory file stores them: ``to_dict`` without the ``LATER_PARAMS`` at
        their defaults (both control keys under rate control), so that files of the default path are
        written as before those parameters existed; ``params_that_differ`` reads a missing one as its
        default."""
        values = self.to_dict()
        tail = {k: values.pop(k) for k in self.STORED_TAIL}
        later = {k: values.pop(k) for k in self.LATER_PARAMS}
        defaults = self.defaults()
        keep = {k for k, v in later.items() if v != defaults[k]}
        if later.get("control") == "rate":
            keep |= {"control", "shear_rate"}
        return {**values, **tail, **{k: v for k, v in later.items() if k in keep}}

    @classmethod
    def defaults(cls) -> dict:
        """Default value of every field (all fields have one)."""
        return {f.name: f.default for f in dataclasses.fields(cls)}

    @classmethod
    def from_mapping(cls, mapping) -> SimParams:
        """Build from a dict-like (e.g. a Hydra ``sim`` node); unknown keys are an error."""
        names = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(mapping) - names)
        if unknown:
            raise ParameterError(f"unknown simulation parameter(s) {unknown}; allowed: {sorted(names)}")
        return cls(**{k: mapping[k] for k in mapping})

    # ---- validation ----------------------------------------------------------------------------
    def validate(self) -> None:
        # types first, so that the range checks below compare numbers (a YAML or command-line string,
        # null or boolean would otherwise fail there with a TypeError, or pass as 0/1)
        for field in dataclasses.fields(self):
            value, default = getattr(self, field.name), field.default
            if isinstance(default, bool):
                ok, expected = isinstance(value, bool), "true or false"
            elif isinstance(default, int):
                ok, expected = (
                    isinstance(value, numbers.Integral) and not isinstance(value, bool),
                    "an integer",
                )
            elif isinstance(default, float):
                ok, expected = isinstance(value, numbers.Real) and not isinstance(value, bool), "a number"
            else:
                ok, expected = isinstance(value, str), "a string"
            if not ok:
                raise ParameterError(f"sim.{field.name}={value!r} is invalid: expected {expected}")

        def check(name, ok, allowed):
            value = getattr(self, name)
            if isinstance(value, float) and not math.isfinite(value):
                ok = False
            if not ok:
                raise ParameterError(f"sim.{name}={value!r} is invalid: allowed {allowed}")

        check("phi", 0.0 < self.phi <= self.PHI_MAX, self.PHI_RULE)
        check("stress", self.stress > 0.0, "stress > 0 (in units of sigma0)")
        check("size_ratio", 1.0 <= self.size_ratio <= 10.0, "1 <= size_ratio <= 10")
        check("strain", self.strain > 0.0, "strain > 0")
        check("mu", self.mu >= 0.0, "mu >= 0")
        # F_CL is the force unit: sigma0 = F_CL / (6 pi a^2), k_n and the graph features' loads are in it
        check("critical_load", self.critical_load == 1.0, "1 (F_CL is the unit of force)")
        check("lub_max_gap", 0.0 < self.lub_max_gap < 1.0, "0 < lub_max_gap < 1")
        check("delta", 0.0 < self.delta < 0.1, "0 < delta < 0.1")
        check("kn_coefficient", self.kn_coefficient > 0.0, "kn_coefficient > 0")
        check("kt_ratio", self.kt_ratio >= 0.0, "kt_ratio >= 0")
        check("disp_max", 0.0 < self.disp_max <= 0.05, "0 < disp_max <= 0.05")
        check("integrator", self.integrator in INTEGRATORS, f"one of {INTEGRATORS}")
        check("lagged_step_control", isinstance(self.lagged_step_control, bool), "true or false")
        check("dt_max", self.dt_max > 0.0, "dt_max > 0")
        check("neighbour_skin", 0.0 < self.neighbour_skin <= 2.0, "0 < neighbour_skin <= 2")
        check("output_interval", 0.0 < self.output_interval <= self.strain, "0 < output_interval <= strain")
        check("snapshot_interval", self.snapshot_interval > 0.0, "snapshot_interval > 0")
        check("steady_state_strain", self.steady_state_strain >= 0.0, "steady_state_strain >= 0")
        check("jam_viscosity", self.jam_viscosity > 1.0, "jam_viscosity > 1")
        check("jam_intervals", self.jam_intervals >= 1, "jam_intervals >= 1")
        check("max_wall_seconds", self.max_wall_seconds >= 0.0, "max_wall_seconds >= 0 (0: unlimited)")
        check("checkpoint_wall_seconds", self.checkpoint_wall_seconds > 0.0, "checkpoint_wall_seconds > 0")
        check("relax_tolerance", self.relax_tolerance > 0.0, "relax_tolerance > 0")
        check("initial_min_gap", 0.0 <= self.initial_min_gap <= 0.1, "0 <= initial_min_gap <= 0.1")
        check("seed", isinstance(self.seed, int) and self.seed >= 0, "integer seed >= 0")
        check("n_particles", isinstance(self.n_particles, int) and self.n_particles >= 2, "integer >= 2")
        check(
            "elastic_unloading",
            isinstance(self.elastic_unloading, bool)
            and (self.integrator == "implicit" or not self.elastic_unloading),
            "true or false; true needs sim.integrator=implicit (its spring holds the contact that sticks)",
        )
        check("control", self.control in CONTROLS, f"one of {CONTROLS}")
        check("shear_rate", self.shear_rate > 0.0, "shear_rate > 0 (gamma0_dot)")
        check("radii", self.radii in RADII, f"one of {RADII}")
        poly = self.radii == "polydisperse"
        check(
            "polydispersity",
            0.0 < self.polydispersity <= POLYDISPERSITY_MAX if poly else self.polydispersity == 0.0,
            f"0 < polydispersity <= {POLYDISPERSITY_MAX} with sim.radii=polydisperse, else 0",
        )
        check(
            "radii_file",
            bool(self.radii_file) if self.radii == "file" else self.radii_file == "",
            "a file of N radii with sim.radii=file, else empty",
        )
        # a radii file is read where the radii are needed (a new run), not wherever its parameters are: a
        # file's stored params stay readable without it; rheograph.sim.radii checks its box then
        if self.radii == "bidisperse":
            self.check_box(self.size_ratio, self.box_length())
        elif self.radii == "polydisperse":
            self.check_box(float(self.particle_radii().max()), self.box_length())
