"""Side by side with LF_DEM: CPU seconds per unit strain, steps per strain and cost per step of rheograph and
of the C++ reference code LF_DEM (public repository ryseto/LF_DEM), both run on one pinned core of this
machine from the same initial configuration, at phi = 0.76, sigma/sigma0 = 10.

    python -m bench.vs_lfdem --lfdem /work/lfdem/bin/LF_DEM                # N = 400, 2000; 3 repeats
    LFDEM_BINARY=/work/lfdem/bin/LF_DEM python -m bench.vs_lfdem --n 400 --strains 0.02 0.04 \\
        --repeats 1 --no-write                                             # a quick check of the script

LF_DEM is not part of this project: build it outside the repository (README.rst of LF_DEM; on Debian
``libsuitesparse-dev`` and a BLAS are enough), e.g.

    git clone https://github.com/ryseto/LF_DEM /work/lfdem/src && cd /work/lfdem/src/LF_DEM
    git checkout 00fa7cc        # the commit of shared/reference (optional)
    sed 's/-lopenblas/-lblas/' config/Makefile_config_Ubuntu_OpenBLAS.mk > config/Makefile_config.mk
    make

Method.  One initial configuration per N is built by rheograph (``initial_configuration`` from the
SimParams seed, exactly what ``simulate.py`` builds) and written in LF_DEM's text configuration format
(header ``# np1 np2 vf lx ly lz vf1 vf2 disp``, then ``x y z radius`` per particle; LF_DEM's plane is x-z,
y = 0).  LF_DEM's parameter file is generated from the same SimParams (the reference file
shared/reference/lfdem_phi0.76/parameters_clm2d.txt with disp_max and time_end set); LF_DEM runs with
``-s <sigma>cl`` (stress control, critical-load units).  rheograph runs as ``simulate.py`` with Hydra
overrides.  Every run is a child process pinned with ``taskset -c CORE`` and single-threaded
(OPENBLAS_NUM_THREADS = OMP_NUM_THREADS = OMP_THREAD_LIMIT = NUMBA_NUM_THREADS = 1); its CPU time is
the user + system time of the child (``os.wait4``).  Start-up (imports, numba cache, relaxation, file
set-up) is removed by running each case to two strain targets from the same start and differencing:
cost per strain = (cpu2 - cpu1) / (strain2 - strain1), likewise steps (LF_DEM: ``timestep_end`` of its
``t_*.dat``; rheograph: the step counter of the trajectory's checkpoint).  The codes alternate run by run,
and the whole set is repeated ``--repeats`` times; medians are reported.  The script checks that both
codes start from the same state: LF_DEM's reported area fraction and box, and its first shear rate
against rheograph's (identical positions give the same rate to LF_DEM's 6 printed digits).

Schemes: rheograph ``euler-lagged`` (LF_DEM's discretisation: explicit Euler, dt from the previous step's
speeds) at ``--disp`` and ``implicit`` at ``--implicit-disp``, against LF_DEM at each ``--lfdem-disp``
(the same disp_max, and the smaller one it needs for the accuracy the implicit scheme has at 2e-3,
docs/validation/time_step.md).  LF_DEM's files stay in a temporary directory.  Results replace the marked
section of docs/validation/speed.md unless ``--no-write``.  Run it alone on the machine.
"""

from __future__ import annotations

import argparse
import os
import shlex
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from bench.publishing import Section, command_line, publish
from bench.publishing import table as table_block
from rheograph.io.hdf5 import POSITION_DECIMALS

ROOT = Path(__file__).resolve().parents[1]
SECTION = "vs_lfdem"
THREAD_ENV = {
    "OPENBLAS_NUM_THREADS": "1",
    "OMP_NUM_THREADS": "1",
    "OMP_THREAD_LIMIT": "1",  # CHOLMOD's OpenMP obeys only this one (see simulate.py)
    "NUMBA_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1",
}
NO_BINARY = (
    "LF_DEM binary not given or not executable{detail}: pass --lfdem PATH or set LFDEM_BINARY. "
    "LF_DEM (github.com/ryseto/LF_DEM) is not part of this project; build it outside the repository, "
    "e.g. `git clone https://github.com/ryseto/LF_DEM /work/lfdem/src && cd /work/lfdem/src/LF_DEM && "
    "sed 's/-lopenblas/-lblas/' config/Makefile_config_Ubuntu_OpenBLAS.mk > config/Makefile_config.mk "
    "&& make` (needs libsuitesparse-dev and a BLAS). Nothing was run."
)


# ---- LF_DEM input files ----------------------------------------------------------------------------
def wrap(positions, lx: float, ly: float) -> np.ndarray:
    """Positions (N, 2) wrapped into [0, lx) x [0, ly)."""
    out = np.mod(np.asarray(positions, dtype=np.float64), [lx, ly])
    out[out[:, 0] >= lx, 0] = 0.0  # np.mod(-1e-17, L) rounds to L
    out[out[:, 1] >= ly, 1] = 0.0
    return out


def write_lfdem_configuration(path, positions, radii, lx: float, ly: float, small_radius: float = 1.0):
    """Write positions (N, 2) and radii (N,) in LF_DEM's text configuration format (2D: the x-z plane,
    ly = 0).  Coordinates are wrapped into [0, L): LF_DEM's imposed flow is zero at z = 0, rheograph's at
    y = 0, so the wrapped coordinates keep every particle's affine velocity.  Floats are written with
    ``repr`` and read back bit for bit."""
    radii = np.asarray(radii, dtype=np.float64)
    x, z = wrap(positions, lx, ly).T
    small = radii <= small_radius
    area = lx * ly
    vf1 = float(np.pi * np.sum(radii[small] ** 2) / area)
    vf2 = float(np.pi * np.sum(radii[~small] ** 2) / area)
    lines = [
        "# np1 np2 vf lx ly lz vf1 vf2 disp",
        f"# {int(small.sum())} {int((~small).sum())} {vf1 + vf2!r} {float(lx)!r} 0 {float(ly)!r} "
        f"{vf1!r} {vf2!r} 0",
    ]
    lines += [f"{float(xi)!r} 0 {float(zi)!r} {float(ai)!r}" for xi, zi, ai in zip(x, z, radii)]
    Path(path).write_text("\n".join(lines) + "\n")


def read_lfdem_configuration(path) -> dict:
    """Parse a text configuration as LF_DEM does (two header lines of keys and values, then
    ``x y z radius``); returns positions (N, 2) in the x-z plane, radii, lx, ly (= LF_DEM's lz), vf."""
    text = Path(path).read_text().splitlines()
    keys, values = text[0].split()[1:], text[1].split()[1:]
    if len(keys) != len(values):
        raise ValueError(f"{path}: ill-formed header")
    meta = dict(zip(keys, values))
    rows = np.array([[float(v) for v in line.split()] for line in text[2:] if line.strip()])
    if float(meta["ly"]) != 0.0 or np.any(rows[:, 1] != 0.0):
        raise ValueError(f"{path}: not a 2D (x-z) configuration")
    return dict(
        positions=rows[:, [0, 2]],
        radii=rows[:, 3],
        lx=float(meta["lx"]),
        ly=float(meta["lz"]),
        vf=float(meta["vf"]),
    )


def lfdem_parameters(params, strain: float) -> str:
    """LF_DEM parameter file of a SimParams (the reference parameters_clm2d.txt, values from ``params``)."""
    if params.mu > 0 and params.critical_load != 1.0:
        raise ValueError("LF_DEM's stress unit is the critical load: critical_load must be 1")
    lines = [
        "/* 2D stress-controlled CLM run, non-Brownian: written by rheograph's bench/vs_lfdem.py */",
        "lubrication_model = tangential;",
        f"lub_max_gap = {params.lub_max_gap:g};",
        f"lub_reduce_parameter = {params.delta:g};",
        "sd_coeff = 1;",
        "friction_model = 2;",
        f"mu_static = {params.mu:g};",
        f"mu_dynamic = {params.mu:g};",
        f"kn = {params.kn_coefficient:g}s;",
        f"kt = {params.kt_ratio:g}kn;",
        "kr = 0kn;",
        "contact_relaxation_time = -1cl;",
        "contact_relaxation_time_tan = -1cl;",
        "integration_method = 0;",
        "fixed_dt = false;",
        f"disp_max = {params.disp_max:g};",
        f"time_end = {strain:g}h;",
        f"time_interval_output_data = {params.output_interval:g}h;",
        f"time_interval_output_config = {params.snapshot_interval:g}h;",
        "out_data_particle = true;",
        "out_data_interaction = true;",
        "origin_zero_flow = true;",
    ]
    return "\n".join(lines) + "\n"


# ---- running and timing a child ------------------------------------------------------------------
def timed_run(cmd: list[str], cwd: Path, core: int | None) -> dict:
    """Run ``cmd`` pinned to ``core`` in ``cwd``; returns CPU (user + system) and wall seconds."""
    if core is not None:
        cmd = ["taskset", "-c", str(core), *cmd]
    env = {**os.environ, **THREAD_ENV}
    with open(cwd / "stdout.log", "w") as out, open(cwd / "stderr.log", "w") as err:
        start = time.perf_counter()
        proc = subprocess.Popen(cmd, cwd=cwd, env=env, stdout=out, stderr=err)
        _, status, usage = os.wait4(proc.pid, 0)
        wall = time.perf_counter() - start
    proc.returncode = os.waitstatus_to_exitcode(status)
    if proc.returncode != 0:
        tail = (cwd / "stderr.log").read_text()[-2000:] + (cwd / "stdout.log").read_text()[-1000:]
        raise RuntimeError(f"{shlex.join(cmd)} failed with exit code {proc.returncode}:\n{tail}")
    return dict(cpu=usage.ru_utime + usage.ru_stime, wall=wall)


def read_lfdem_run(run_dir: Path) -> dict:
    """Strain reached, total steps, first-row shear rate, area fraction and box of an LF_DEM run."""
    (data,) = run_dir.glob("data_*.dat")
    (tfile,) = run_dir.glob("t_*.dat")
    header, rows, version = {}, [], ""
    for line in data.read_text().splitlines():
        if line.startswith("# LF_DEM version"):
            version = line.split()[-1]
        elif line.startswith("# ") and len(line.split()) == 3:
            header[line.split()[1]] = line.split()[2]
        elif line.strip() and not line.startswith("#"):
            rows.append(line.split())
    # t_*.dat: "# np time_from_0 time_from_1 timestep_end timestep_from_1"
    steps = int(tfile.read_text().splitlines()[-1].split()[3])
    return dict(
        strain=float(rows[-1][1]),  # column 2: cumulated shear strain
        steps=steps,
        rate0=float(rows[0][2]),  # column 3: shear rate
        vf=float(header["VF"]),
        lx=float(header["Lx"]),
        lz=float(header["Lz"]),
        version=version,
    )


def read_rheograph_run(path: Path) -> dict:
    import h5py

    with h5py.File(path, "r") as h5:
        cp = h5["checkpoint"].attrs
        return dict(
            strain=float(cp["strain"]),
            steps=int(cp["steps"]),
            rate0=float(h5["timeseries/shear_rate"][0]),
            positions0=h5["snapshots/positions"][0],
            radii=h5["radii"][()],
            lx=float(h5.attrs["lx"]),
        )


class Case:
    """One code + scheme + disp_max at one N; ``run(strain)`` gives CPU seconds, steps, strain reached."""

    def __init__(self, code, scheme, disp, params, binary=None, conf=None):
        self.code, self.scheme, self.disp, self.params = code, scheme, disp, params
        self.binary, self.conf = binary, conf

    @property
    def label(self) -> str:
        return f"{self.code} {self.scheme} {self.disp:g}"

    def run(self, strain: float, work: Path, core: int | None) -> dict:
        import dataclasses

        run_dir = Path(tempfile.mkdtemp(prefix=f"{self.code}_", dir=work))
        p = dataclasses.replace(self.params, strain=strain)
        if self.code == "LF_DEM":
            (run_dir / "params.txt").write_text(lfdem_parameters(p, strain))
            shutil.copy(self.conf, run_dir / "conf.dat")
            cmd = [str(self.binary), "-s", f"{p.stress:g}cl", "conf.dat", "params.txt"]
            timing = timed_run(cmd, run_dir, core)
            result = read_lfdem_run(run_dir)
        else:
            from rheograph.naming import run_name

            cmd = [sys.executable, str(ROOT / "simulate.py"), *hydra_overrides(p, run_dir)]
            timing = timed_run(cmd, run_dir, core)
            result = read_rheograph_run(run_dir / run_name(p) / "trajectory.h5")
        result.update(timing, run_dir=run_dir)
        return result


def hydra_overrides(p, output_root: Path) -> list[str]:
    return [
        "sim=n400",  # physics.md defaults; the fields below set the state point and the scheme
        f"sim.n_particles={p.n_particles}",
        f"sim.phi={p.phi!r}",
        f"sim.stress={p.stress!r}",
        f"sim.seed={p.seed}",
        f"sim.strain={p.strain!r}",
        f"sim.disp_max={p.disp_max!r}",
        f"sim.integrator={p.integrator}",
        f"sim.lagged_step_control={str(p.lagged_step_control).lower()}",
        f"output_root={output_root}",
        "progress=false",
    ]


def check_same_start(n, conf_file, lf: dict, rg: dict, params) -> str:
    """Both codes read the same configuration: box, area fraction, positions and the first shear rate."""
    conf = read_lfdem_configuration(conf_file)
    box = params.box_length()
    phi = float(np.pi * np.sum(conf["radii"] ** 2) / box**2)
    problems = []
    # a finished run stores its snapshot positions to 1e-7 a (rheograph.io.hdf5.AT_REST): equal up to that
    offset = wrap(rg["positions0"], rg["lx"], rg["lx"]) - conf["positions"]
    offset -= rg["lx"] * np.round(offset / rg["lx"])
    if np.abs(offset).max() > 10.0**-POSITION_DECIMALS:
        problems.append("rheograph's initial positions differ from the file written for LF_DEM")
    if not np.array_equal(rg["radii"], conf["radii"]):
        problems.append("radii differ")
    if abs(lf["vf"] - phi) > 1e-5 or abs(lf["lx"] - box) > 1e-3 or abs(lf["lz"] - box) > 1e-3:
        problems.append(
            f"LF_DEM read phi={lf['vf']}, box {lf['lx']} x {lf['lz']} (ours {phi:.6f}, {box:.4f})"
        )
    rel = abs(lf["rate0"] - rg["rate0"]) / abs(rg["rate0"])
    if rel > 1e-5:  # LF_DEM prints 6 significant digits
        problems.append(f"first shear rate LF_DEM {lf['rate0']:.6g} vs rheograph {rg['rate0']:.7g}")
    if problems:
        raise RuntimeError(f"N = {n}: the two codes do not start from the same state: " + "; ".join(problems))
    return (
        f"N = {n}: same start checked — LF_DEM reads φ = {lf['vf']:g}, L = {lf['lx']:g} (ours {phi:.6f}, "
        f"{box:.4f}); initial γ̇ LF_DEM {lf['rate0']:.6g} vs rheograph {rg['rate0']:.7g} "
        f"(relative difference {rel:.1e})"
    )


def measure(args, binary: Path, work: Path) -> tuple[list[dict], list[str], str]:
    from rheograph.sim import SimParams
    from rheograph.sim.init_config import initial_configuration
    from rheograph.sim.params import scheme_settings

    g1, g2 = args.strains
    rows, checks, version = [], [], ""
    for n in args.n:
        base = SimParams(n_particles=n, phi=args.phi, stress=args.stress, seed=args.seed, strain=g2)
        pos, radii, box = initial_configuration(base)  # what Simulation(base) starts from
        conf = work / f"conf_N{n}.dat"
        write_lfdem_configuration(conf, pos, radii, box, box)
        ours = []
        for scheme in args.schemes:
            disp = args.implicit_disp if scheme.startswith("implicit") else args.disp
            p = SimParams(**{**base.to_dict(), "disp_max": disp, **scheme_settings(scheme)})
            ours.append(Case("rheograph", scheme, disp, p))
        theirs = []
        for disp in args.lfdem_disp:
            p = SimParams(**{**base.to_dict(), "disp_max": disp, **scheme_settings("euler-lagged")})
            theirs.append(Case("LF_DEM", "euler", disp, p, binary=binary, conf=conf))
        # alternate the codes: LF_DEM, rheograph, LF_DEM, rheograph, ...
        order = [c for pair in zip(theirs, ours) for c in pair]
        order += theirs[len(ours) :] + ours[len(theirs) :]
        # warm-up (numba cache, page cache) and the same-start check, untimed
        first = {c.code: c.run(args.check_strain, work, args.core) for c in (theirs[0], ours[0])}
        version = first["LF_DEM"]["version"]
        checks.append(check_same_start(n, conf, first["LF_DEM"], first["rheograph"], base))
        print(checks[-1], flush=True)
        for c in ours[1:]:
            c.run(args.check_strain, work, args.core)
        samples = {c.label: [] for c in order}
        for rep in range(args.repeats):
            for c in order:
                r1 = c.run(g1, work, args.core)
                r2 = c.run(g2, work, args.core)
                d_strain, d_steps, d_cpu = (
                    r2["strain"] - r1["strain"],
                    r2["steps"] - r1["steps"],
                    r2["cpu"] - r1["cpu"],
                )
                sample = dict(
                    cpu_per_strain=d_cpu / d_strain,
                    steps_per_strain=d_steps / d_strain,
                    ms_per_step=1e3 * d_cpu / d_steps,
                    us_per_particle_step=1e6 * d_cpu / (d_steps * n),
                )
                samples[c.label].append(sample)
                print(
                    f"N={n} repeat {rep + 1}/{args.repeats} {c.label}: "
                    f"cpu {r1['cpu']:.1f} / {r2['cpu']:.1f} s at strain {r1['strain']:.4f} / "
                    f"{r2['strain']:.4f}, steps {r1['steps']} / {r2['steps']} -> "
                    f"{sample['cpu_per_strain']:.1f} CPU s/strain, {sample['ms_per_step']:.2f} ms/step",
                    flush=True,
                )
                if not args.keep:
                    shutil.rmtree(r1["run_dir"])
                    shutil.rmtree(r2["run_dir"])
        for c in ours + theirs:
            s = samples[c.label]
            med = {k: statistics.median(x[k] for x in s) for k in s[0]}
            rows.append(dict(n=n, code=c.code, scheme=c.scheme, disp=c.disp, repeats=len(s), **med))
    return rows, checks, version


def table(rows: list[dict], lfdem_disps: list[float]) -> dict:
    """A table block: each code's cost, and LF_DEM's over this one's at each LF_DEM disp_max."""
    header = [
        "N",
        "code",
        "scheme",
        "disp_max",
        "CPU s/strain",
        "steps/strain",
        "ms/step",
        "µs/particle-step",
    ]
    header += [f"LF_DEM {d:g} / this (CPU per strain)" for d in lfdem_disps]
    body = []
    for r in rows:
        refs = {x["disp"]: x for x in rows if x["n"] == r["n"] and x["code"] == "LF_DEM"}
        ratios = [
            f"{refs[d]['cpu_per_strain'] / r['cpu_per_strain']:.2f}"
            if d in refs and r["code"] != "LF_DEM"
            else "–"
            for d in lfdem_disps
        ]
        body.append(
            [f"{r['n']}", r["code"], r["scheme"], f"{r['disp']:g}", f"{r['cpu_per_strain']:.1f}"]
            + [f"{r['steps_per_strain']:.0f}", f"{r['ms_per_step']:.2f}", f"{r['us_per_particle_step']:.2f}"]
            + ratios
        )
    return table_block(header, body)


def find_binary(given: str | None) -> tuple[Path | None, str]:
    candidate = given or os.environ.get("LFDEM_BINARY")
    if not candidate:
        return None, ""
    path = Path(candidate).expanduser()
    if not (path.is_file() and os.access(path, os.X_OK)):
        return None, f" ({path} is not an executable file)"
    return path.resolve(), ""


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--lfdem", help="LF_DEM binary (default: $LFDEM_BINARY)")
    ap.add_argument("--n", type=int, nargs="+", default=[400, 2000])
    ap.add_argument("--phi", type=float, default=0.76)
    ap.add_argument("--stress", type=float, default=10.0, help="sigma / sigma0")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument(
        "--strains",
        type=float,
        nargs=2,
        default=[0.2, 0.6],
        metavar=("G1", "G2"),
        help="the two strain targets; costs are differences between them (G1 past the start-up transient)",
    )
    ap.add_argument("--schemes", nargs="+", default=["euler-lagged", "implicit"], help="rheograph schemes")
    ap.add_argument("--disp", type=float, default=2e-3, help="disp_max of rheograph's explicit schemes")
    ap.add_argument(
        "--implicit-disp", type=float, default=2e-3, help="disp_max of rheograph's implicit scheme"
    )
    ap.add_argument(
        "--lfdem-disp", type=float, nargs="+", default=[2e-3, 5e-4], help="LF_DEM's disp_max values"
    )
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--core", type=int, default=0, help="CPU core every run is pinned to (taskset -c)")
    ap.add_argument("--check-strain", type=float, default=0.01, help=argparse.SUPPRESS)
    ap.add_argument("--keep", action="store_true", help="keep the run directories (printed at the end)")
    ap.add_argument("--no-write", action="store_true")
    args = ap.parse_args(argv)

    binary, detail = find_binary(args.lfdem)
    if binary is None:
        print(NO_BINARY.format(detail=detail), flush=True)
        return 0
    if args.strains[1] <= args.strains[0]:
        ap.error("--strains G1 G2 needs G2 > G1")
    if shutil.which("taskset") is None:
        print("taskset not found: runs are not pinned to a core", flush=True)
        args.core = None
    else:
        os.sched_setaffinity(0, {args.core})  # this process too (it builds the configurations)

    work = Path(tempfile.mkdtemp(prefix="vs_lfdem_"))
    started = time.time()
    try:
        rows, checks, version = measure(args, binary, work)
    finally:
        if args.keep:
            print(f"run directories kept in {work}")
        else:
            shutil.rmtree(work, ignore_errors=True)
    command = command_line("vs_lfdem.py", argv)
    for n in args.n:  # one section per system size, so that sizes can be measured in separate runs
        out = Section(
            f"### Side by side with LF_DEM, N = {n}",
            "",
            f"Machine: {os.cpu_count()} cores; every run a child process pinned to core {args.core}, "
            "single-threaded (OPENBLAS/OMP/NUMBA threads 1, OMP_THREAD_LIMIT=1); CPU = user + system time "
            f"of the child.  φ = {args.phi:g}, σ/σ0 = {args.stress:g}, seed {args.seed}; both codes start "
            "from one configuration (built by rheograph, written in LF_DEM's format).  Costs are differences "
            f"between runs to strain {args.strains[0]:g} and {args.strains[1]:g} from the same start "
            f"(start-up removed); codes alternate; medians of {args.repeats} repeat(s).  LF_DEM "
            f"{version or '(version unknown)'}, explicit Euler, `-s <σ>cl`; rheograph `simulate.py`, "
            "solver auto.",
            "",
        )
        out.table(**table([r for r in rows if r["n"] == n], args.lfdem_disp)["table"])
        out.add(
            "",
            *[f"* {c}" for c in checks if c.startswith(f"N = {n}:")],
            "",
            f"Command (wall {time.time() - started:.0f} s): `{command}`",
        )
        publish(
            f"{SECTION}_n{n}",
            out,
            not args.no_write,
            page="validation/speed.md",
            command=command,
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
