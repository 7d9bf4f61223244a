"""Side by side with LF_DEM in 3D: the same start, the same parameters, the same scheme.

    # strain-0 check only (first shear rate, velocities, stress tensor against LF_DEM's first outputs)
    python -m bench.vs_lfdem_3d --strain 0
    # and a run of ours to strain 2 at sigma/sigma0 = 10: CPU s per strain, eta_r, Pi/sigma, Z, Z_mu
    python -m bench.vs_lfdem_3d --strain 2 --stress 10
    # the rate-controlled point (LF_DEM -r 0.1cl with the stiffness of sigma/sigma0 = 10)
    python -m bench.vs_lfdem_3d --strain 2 --control rate --rate 0.1 --stress 10
    # from LF_DEM's N = 2000 start (its reference run stops at strain 0.25: a cost window, not a steady one)
    python -m bench.vs_lfdem_3d --reference data/lfdem_reference_3d/phi0.56_n2000 \
        --configuration D3N2000VF0.56Bidi1.4_0.5Cubic_1_.dat --strain 0.25 --steady 0.05 --stress 10

Reads LF_DEM's 3D start (data/lfdem_reference_3d/phi0.56_n500/D3N500VF0.56Bidi1.4_0.5Cubic_1_.dat, made
by LF_DEM's own generator) and the LF_DEM outputs of the same state point (its README lists them), and runs
``rheograph.sim.integrator3d.Simulation3D`` from that configuration with LF_DEM's parameters and scheme:
explicit Euler with the lagged step control (dt from the previous step's speeds), disp_max as given.
``--scheme implicit`` runs ours with the default scheme instead (linearly implicit springs, current-speed
step control) at ``--disp-max``, against LF_DEM's run at ``--lfdem-disp-max``: the same start, another
discretisation, for the cost at equal accuracy; ``--scheme implicit-unloading`` adds the elastic unloading
of sliding contacts (``sim.elastic_unloading``).

Axes.  LF_DEM shears along x with gradient z and vorticity y; ours along x with gradient y and vorticity z.
The proper rotation (x, y, z)_ours = (x, z, -y)_LF_DEM maps one onto the other (geometry3d's docstring):
positions, velocities and angular velocities as vectors, stresses as tensors (sigma_xy ours = sigma_xz
LF_DEM, sigma_yy = sigma_zz, sigma_zz = sigma_yy, sigma_xz = -sigma_xy, sigma_yz = -sigma_yz).  LF_DEM's
configuration file has positions in [0, L)^3; its particle output (origin_zero_flow) shifts them to
[-L/2, L/2)^3 with u_inf = rate * z: x - L/2, y - L/2, z wrapped (at strain 0 nothing else).  We use that
frame, rotated, as our box [-L/2, L/2)^3 with u_inf = rate * y.  Lengths are in units of the small radius
in both codes (LF_DEM's radii are 1 and 1.4); stresses in sigma0 = F_CL / (6 pi a^2) and rates in
F_CL / (6 pi eta0 a^2) in both (LF_DEM's "cl" output units).

Strain 0.  Identical positions must give the same first shear rate and velocities to LF_DEM's 6 printed
digits (its ``par_`` file at strain 0 and the first rows of ``data_`` and ``st_``).

Run.  Our run samples the shear rate, Pi, Z and Z_mu on the first step at or after each multiple of 0.01
strain (LF_DEM writes exactly there), and the steady means over strain >= --steady are computed by the same
estimator for both codes (``rheograph.analysis.steady.steady_state_summary``: eta_r = sigma * elapsed time /
elapsed strain, strain-weighted means, 5 block standard errors).  Under rate control eta_r = <sigma_xy>/rate.
CPU: ``time.process_time`` of this process over the steps after --warmup-strain (numba compilation and
caches excluded); LF_DEM's CPU per strain is measured outside (its README).  Run it alone on one core:
OPENBLAS_NUM_THREADS / OMP_THREAD_LIMIT / NUMBA_NUM_THREADS are set to 1 here.  Nothing is tuned: the
parameters are those of LF_DEM's parameter file.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

for _var in (
    "OPENBLAS_NUM_THREADS",
    "OMP_NUM_THREADS",
    "OMP_THREAD_LIMIT",
    "NUMBA_NUM_THREADS",
    "MKL_NUM_THREADS",
):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402

from rheograph.analysis.steady import steady_state_summary  # noqa: E402
from rheograph.sim.geometry3d import wrap_positions  # noqa: E402
from rheograph.sim.integrator3d import SimState3D, Simulation3D  # noqa: E402
from rheograph.sim.params3d import SimParams3D  # noqa: E402
from rheograph.sim.stress3d import particle_pressure  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
REFERENCE = ROOT / "data" / "lfdem_reference_3d" / "phi0.56_n500"
CONF = "D3N500VF0.56Bidi1.4_0.5Cubic_1_.dat"
# our schemes: LF_DEM's (explicit Euler, lagged step control), the implicit springs, and those with the
# elastic unloading of sliding contacts; the labels of the published tables
SCHEME_LABELS = {
    "euler-lagged": "Euler (lagged)",
    "implicit": "implicit",
    "implicit-unloading": "implicit + unloading",
}
SCHEMES = tuple(SCHEME_LABELS)
# our stress storage (xx, xy, xz, yy, yz, zz) from LF_DEM's st_ order (xx, xy, xz, yz, yy, zz) with
# (x, y, z)_ours = (x, z, -y)_LF: sigma_XX = xx, sigma_XY = xz, sigma_XZ = -xy, sigma_YY = zz,
# sigma_YZ = -yz, sigma_ZZ = yy
LF_ST_TO_OURS = ((0, 1.0), (2, 1.0), (1, -1.0), (5, 1.0), (3, -1.0), (4, 1.0))


# ---- LF_DEM files ---------------------------------------------------------------------------------
def read_configuration(path) -> dict:
    """LF_DEM's 3D text configuration: header ``# np1 np2 vf lx ly lz vf1 vf2 disp`` and its values, then
    ``x y z radius`` per particle (LF_DEM axes, positions in [0, L))."""
    text = Path(path).read_text().splitlines()
    keys, values = text[0].split()[1:], text[1].split()[1:]
    if len(keys) != len(values):
        raise ValueError(f"{path}: ill-formed header")
    meta = {k: float(v) for k, v in zip(keys, values)}
    rows = np.array([[float(v) for v in line.split()] for line in text[2:] if line.strip()])
    if meta["ly"] == 0.0:
        raise ValueError(f"{path}: a 2D configuration (ly = 0)")
    return dict(
        positions=rows[:, :3],
        radii=rows[:, 3],
        lx=meta["lx"],
        ly=meta["ly"],
        lz=meta["lz"],
        vf=meta["vf"],
        n_small=int(meta["np1"]),
        n_large=int(meta["np2"]),
    )


def lfdem_to_ours(v: np.ndarray) -> np.ndarray:
    """Vectors (N, 3) from LF_DEM axes to ours: (x, y, z) -> (x, z, -y)."""
    return np.stack([v[:, 0], v[:, 2], -v[:, 1]], axis=1)


def start_positions(conf: dict) -> np.ndarray:
    """Our start: LF_DEM's output frame at strain 0 (x - Lx/2, y - Ly/2, z wrapped into [-Lz/2, Lz/2)),
    rotated into our axes and wrapped into [-L/2, L/2)^3."""
    p = conf["positions"].copy()
    p[:, 0] -= 0.5 * conf["lx"]
    p[:, 1] -= 0.5 * conf["ly"]
    p[:, 2] -= conf["lz"] * (p[:, 2] >= 0.5 * conf["lz"])
    ours = np.ascontiguousarray(lfdem_to_ours(p))
    wrap_positions(ours, conf["lx"], conf["lz"], conf["ly"], 0.0)
    return ours


def read_first_par(path) -> dict:
    """The first snapshot of LF_DEM's 3D ``par_`` file: header values and per particle radius, position,
    velocity and angular velocity (LF_DEM axes, output frame)."""
    header, rows, started = {}, [], False
    with open(path) as fh:
        for line in fh:
            if line.startswith("# ") and ":" in line:
                if started and rows:
                    break
                key, value = line[2:].split(":", 1)
                header[key.strip()] = float(value)
                started = True
            elif line.strip() and not line.startswith("#") and started:
                rows.append([float(v) for v in line.split()])
    a = np.array(rows)
    return dict(
        strain=header["cumulated strain"],
        rate=header["shear rate"],
        radius=a[:, 1],
        position=a[:, 2:5],
        velocity=a[:, 5:8],
        angular=a[:, 8:11],
    )


def read_table(path) -> tuple[dict, np.ndarray]:
    """An LF_DEM time series: the ``#k: name`` / ``#k-l: name`` header as {name: first column (0-based)}
    and the numbers."""
    names = {}
    for line in Path(path).read_text().splitlines():
        if line.startswith("#") and ":" in line and line[1:2].isdigit():
            cols, name = line[1:].split(":", 1)
            names[name.strip()] = int(cols.split("-")[0]) - 1
    return names, np.loadtxt(path, comments="#")


def lfdem_series(data_path, st_path, stress: float, control: str) -> dict:
    """What the comparison needs from LF_DEM's data_ and st_ files, columns found by header name."""
    names, d = read_table(data_path)
    snames, st = read_table(st_path)
    n = min(d.shape[0], st.shape[0])
    d, st = d[:n], st[:n]
    total = snames["total stress tensor (xx, xy, xz, yz, yy, zz)"]
    return dict(
        time=d[:, names["time"]],
        strain=d[:, names["cumulated shear strain"]],
        rate=d[:, names["shear rate"]],
        viscosity=d[:, names["viscosity"]],
        pressure=d[:, names["particle pressure"]],
        z=d[:, names["contact number"]],
        z_mu=d[:, names["frictional contact number"]],
        shear_stress=st[:, total + 2],  # xz
        stress_tensor=st[:, total : total + 6],
    )


def steady(series: dict, stress: float, control: str, rate: float, strain_min: float) -> dict:
    """Steady means with block errors; Pi / sigma with sigma the imposed stress (stress control) or the
    mean shear stress (rate control)."""
    out = steady_state_summary(
        series["strain"],
        series["time"],
        series["pressure"],
        series["z_mu"],
        series["z"],
        stress,
        strain_min,
    )
    if control == "stress":
        sigma, sigma_se = stress, 0.0
    else:
        # the same estimator with the shear stress in the place of the pressure gives <sigma_xy>
        tau = steady_state_summary(
            series["strain"],
            series["time"],
            series["shear_stress"],
            series["z_mu"],
            series["z"],
            stress,
            strain_min,
        )
        sigma, sigma_se = tau["pressure"], tau["pressure_se"]
        out["viscosity"], out["viscosity_se"] = sigma / rate, sigma_se / rate
        out["shear_stress"], out["shear_stress_se"] = sigma, sigma_se
    out["pressure_over_sigma"] = out["pressure"] / sigma
    out["pressure_over_sigma_se"] = out["pressure_se"] / sigma
    return out


# ---- our run ----------------------------------------------------------------------------------------
def make_simulation(conf: dict, args) -> Simulation3D:
    n = conf["radii"].shape[0]
    params = SimParams3D(
        n_particles=n,
        phi=conf["vf"],
        stress=args.stress,
        strain=max(args.strain, 0.01),
        mu=0.5,
        kn_coefficient=2e4,
        kt_ratio=0.5,
        delta=1e-3,
        lub_max_gap=0.5,
        integrator="euler" if args.scheme == "euler-lagged" else "implicit",
        lagged_step_control=args.scheme == "euler-lagged",
        elastic_unloading=args.scheme == "implicit-unloading",
        disp_max=args.disp_max,
        control=args.control,
        shear_rate=args.rate,
    )
    box = params.box_length()
    if params.species_counts() != (conf["n_small"], conf["n_large"]):
        raise RuntimeError(
            f"species {params.species_counts()} vs LF_DEM's {conf['n_small'], conf['n_large']}"
        )
    if not (abs(box - conf["lx"]) < 1e-9 * box and conf["lx"] == conf["ly"] == conf["lz"]):
        raise RuntimeError(f"box {box!r} vs LF_DEM's {conf['lx']!r} {conf['ly']!r} {conf['lz']!r}")
    state = SimState3D(
        positions=start_positions(conf),
        radii=conf["radii"].copy(),
        lx=conf["lx"],
        ly=conf["lz"],
        lz=conf["ly"],
    )
    return Simulation3D(params, state=state, solver=args.solver)


def strain_zero_check(
    sim: Simulation3D, par: dict, lf: dict, n: int, angular_unit: float = 1.0
) -> tuple[dict, list[str]]:
    """One step of ours from the start against LF_DEM's strain-0 outputs.  ``angular_unit`` converts the
    ``par_`` file's angular velocities to σ0 units: LF_DEM writes them unconverted, in its internal unit,
    which under rate control is the imposed rate (its Simulation.cpp, "angular velocity" written with unit
    "none"; the translational velocities are converted)."""
    s = sim.state
    start = s.positions.copy()
    res = sim.step(record=True)
    rate = res.shear_rate
    vel = sim.velocity.reshape(n, 6)
    u_total = vel[:, :3].copy()
    u_total[:, 0] += rate * start[:, 1]
    w_total = vel[:, 3:].copy()
    w_total[:, 2] += -0.5 * rate
    lf_pos = lfdem_to_ours(par["position"])
    lf_u = lfdem_to_ours(par["velocity"])
    lf_w = angular_unit * lfdem_to_ours(par["angular"])
    lf_sigma = np.array([sign * lf["stress_tensor"][0, k] for k, sign in LF_ST_TO_OURS])
    ours_sigma = res.stress

    def rel(a, b):  # worst difference relative to the largest magnitude of b
        return float(np.abs(a - b).max() / np.abs(b).max())

    out = dict(
        rate_lfdem=float(lf["rate"][0]),
        rate_ours=float(rate),
        rate_rel=abs(rate - lf["rate"][0]) / abs(lf["rate"][0]),
        positions_max_abs=float(np.abs(start - lf_pos).max()),
        velocity_rel=rel(u_total, lf_u),
        angular_rel=rel(w_total, lf_w),
        stress_lfdem=lf_sigma.tolist(),
        stress_ours=ours_sigma.tolist(),
        stress_rel=rel(ours_sigma, lf_sigma),
        pressure_lfdem=float(lf["pressure"][0]),
        pressure_ours=particle_pressure(ours_sigma),
    )
    problems = []
    if out["positions_max_abs"] > 1e-5 * s.lx:
        problems.append(f"positions differ by {out['positions_max_abs']:.2e} (axis mapping?)")
    if not np.array_equal(par["radius"], s.radii):
        problems.append("radii differ from the par_ file's")
    for key, tol in (("rate_rel", 1e-5), ("velocity_rel", 1e-5), ("angular_rel", 1e-5), ("stress_rel", 1e-5)):
        if out[key] > tol:
            problems.append(f"{key} = {out[key]:.2e} > {tol:g} (LF_DEM prints 6 digits)")
    return out, problems


def run_ours(sim: Simulation3D, args, n: int) -> tuple[dict, dict]:
    """Run to --strain, sampling at every 0.01 strain; CPU per strain after --warmup-strain."""
    s = sim.state
    rows = []
    next_sample = 0.0
    cpu0 = strain0 = steps0 = None
    t_start = time.process_time()
    while s.strain < args.strain:
        if args.max_cpu and time.process_time() - t_start > args.max_cpu:
            print(f"  --max-cpu {args.max_cpu:g} s reached at strain {s.strain:.3f}", flush=True)
            break
        record = s.strain >= next_sample - 1e-12
        if cpu0 is None and s.strain >= args.warmup_strain:
            cpu0, strain0, steps0 = time.process_time(), s.strain, s.steps
        t_before, strain_before = s.time, s.strain
        res = sim.step(record=record)
        if record:
            rows.append(
                (
                    t_before,
                    strain_before,
                    res.shear_rate,
                    particle_pressure(res.stress),
                    2.0 * res.n_contacts / n,
                    2.0 * res.n_frictional / n,
                    res.stress[1],
                )
            )
            next_sample = np.floor(strain_before / 0.01 + 1e-9) * 0.01 + 0.01
            if args.progress and len(rows) % 10 == 0:
                print(
                    f"  strain {strain_before:.3f} rate {res.shear_rate:.5g} steps {s.steps} "
                    f"cpu {time.process_time() - t_start:.0f} s",
                    flush=True,
                )
    cpu1 = time.process_time()
    a = np.array(rows)
    series = dict(
        time=a[:, 0],
        strain=a[:, 1],
        rate=a[:, 2],
        pressure=a[:, 3],
        z=a[:, 4],
        z_mu=a[:, 5],
        shear_stress=a[:, 6],
    )
    cost = dict(cpu_total=cpu1 - t_start, steps=s.steps, strain=s.strain, solver=sim.solver.name)
    if cpu0 is not None and s.strain > strain0:
        cost.update(
            cpu_per_strain=(cpu1 - cpu0) / (s.strain - strain0),
            steps_per_strain=(s.steps - steps0) / (s.strain - strain0),
            ms_per_step=1e3 * (cpu1 - cpu0) / max(1, s.steps - steps0),
            window=(strain0, s.strain),
        )
    return series, cost


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reference", type=Path, default=REFERENCE, help="folder with LF_DEM's files")
    ap.add_argument(
        "--configuration",
        default=CONF,
        help="LF_DEM's start in --reference (its generator's file name)",
    )
    ap.add_argument("--stress", type=float, default=10.0, help="sigma/sigma0 (rate control: stiffness scale)")
    ap.add_argument("--control", choices=("stress", "rate"), default="stress")
    ap.add_argument("--rate", type=float, default=0.1, help="imposed rate under --control rate")
    ap.add_argument("--disp-max", type=float, default=1e-3, help="our step's disp_max")
    ap.add_argument(
        "--scheme",
        choices=SCHEMES,
        default="euler-lagged",
        help="ours: LF_DEM's scheme (explicit Euler, lagged step control), the default implicit one, or the "
        "implicit one with elastic unloading of sliding contacts",
    )
    ap.add_argument(
        "--solver",
        default="auto",
        choices=("auto", "cholmod", "qdldl", "amg"),
        help="our linear solver (rheograph.sim.solver)",
    )
    ap.add_argument("--lfdem-disp-max", type=float, help="the LF_DEM run compared with (default: --disp-max)")
    ap.add_argument("--strain", type=float, default=0.0, help="0: the strain-0 check only")
    ap.add_argument("--steady", type=float, default=1.0, help="steady window starts at this strain")
    ap.add_argument(
        "--max-cpu", type=float, default=0.0, help="stop our run after this many CPU s (0: no cap)"
    )
    ap.add_argument("--warmup-strain", type=float, default=0.05)
    ap.add_argument("--lfdem-data", type=Path, help="LF_DEM data_ file (default: from --reference)")
    ap.add_argument("--par", type=Path, help="LF_DEM par_ file with the strain-0 snapshot")
    ap.add_argument("--json", type=Path, help="write the numbers here")
    ap.add_argument(
        "--ours",
        type=Path,
        help="our series from an earlier --json of the same settings: compared again, not rerun",
    )
    ap.add_argument(
        "--campaign",
        nargs="+",
        default=[],
        help="trajectory files of the same state point run by simulate.py (own start and scheme): "
        "their steady values (mean over the files) in a column of their own",
    )
    ap.add_argument("--section", help="publish the steady comparison as this section of --page")
    ap.add_argument("--page", default="validation/lfdem_3d.md")
    ap.add_argument("--progress", action="store_true")
    args = ap.parse_args(argv)

    tag = f"s{args.stress:g}" if args.control == "stress" else f"r{args.rate:g}"
    lfdem_disp = args.lfdem_disp_max or args.disp_max
    data_path = args.lfdem_data or args.reference / f"data_{tag}_disp{lfdem_disp:.0e}.dat".replace(
        "e-0", "e-"
    )
    st_path = data_path.with_name(data_path.name.replace("data_", "st_", 1))
    for path in (data_path, st_path):
        if not path.exists() and path.with_suffix(path.suffix + ".gz").exists():
            raise SystemExit(f"{path}.gz: gunzip it first (gunzip -k {path}.gz)")
    conf_path = args.reference / args.configuration
    if not conf_path.is_file():
        raise SystemExit(f"--configuration {conf_path}: not found (LF_DEM's generator output in --reference)")
    conf = read_configuration(conf_path)
    n = conf["radii"].shape[0]
    lf = lfdem_series(data_path, st_path, args.stress, args.control)
    report: dict = dict(
        command=" ".join([Path(sys.argv[0]).name, *(argv or sys.argv[1:])]),
        lfdem_data=str(data_path.relative_to(ROOT) if data_path.is_relative_to(ROOT) else data_path),
    )

    problems: list[str] = []
    if args.scheme == "euler-lagged":  # the strain-0 check is of LF_DEM's own scheme
        sim = make_simulation(conf, args)
        par_path = args.par or data_path.with_name(data_path.name.replace("data_", "par0_", 1))
        t0 = time.process_time()
        if par_path.exists():
            angular_unit = args.rate if args.control == "rate" else 1.0
            check, problems = strain_zero_check(sim, read_first_par(par_path), lf, n, angular_unit)
        else:  # without the particle file: the first shear rate and stress only
            check, problems = strain_zero_check_rate_only(sim, lf)
        check["cpu_first_step_s"] = time.process_time() - t0
        report["strain0"] = check
        print(
            f"strain 0: shear rate LF_DEM {check['rate_lfdem']:.6g} ours {check['rate_ours']:.7g} "
            f"(rel {check['rate_rel']:.1e})",
            end="",
        )
        if "velocity_rel" in check:
            print(
                f"; velocities rel {check['velocity_rel']:.1e}, angular {check['angular_rel']:.1e}, "
                f"stress tensor rel {check['stress_rel']:.1e}",
                end="",
            )
        print(f"; Pi LF_DEM {check['pressure_lfdem']:.6g} ours {check['pressure_ours']:.7g}")
        for p in problems:
            print("  DISAGREES:", p)

    if args.ours is not None:
        series, cost = earlier_series(args.ours, args)
    elif args.strain > 0:
        # a fresh simulation from the same start: the check's step has already moved the first one
        sim = make_simulation(conf, args)
        series, cost = run_ours(sim, args, n)
    if args.ours is not None or args.strain > 0:
        report["settings"] = settings(args)
        report["cost_ours"] = cost
        report["series_ours"] = {k: v.tolist() for k, v in series.items()}
        if "cpu_per_strain" in cost:
            w0, w1 = cost["window"]
            print(
                f"ours: {cost['cpu_per_strain']:.1f} CPU s/strain, "
                f"{cost['steps_per_strain']:.0f} steps/strain, "
                f"{cost['ms_per_step']:.2f} ms/step over strain {w0:.3f}-{w1:.3f}"
            )
        lf_end = min(float(lf["strain"][-1]), float(series["strain"][-1]) + 0.01)
        keep = lf["strain"] <= lf_end
        lf_cut = {k: v[keep] for k, v in lf.items()}
        a = steady(lf_cut, args.stress, args.control, args.rate, args.steady)
        b = steady(series, args.stress, args.control, args.rate, args.steady)
        report["steady"] = dict(window=(args.steady, lf_end), lfdem=a, ours=b)
        print(
            f"steady window strain {args.steady:g}-{lf_end:.2f} "
            f"(LF_DEM rows {a.get('n_rows')}, ours {b.get('n_rows')}):"
        )
        for key, label in (
            ("viscosity", "eta_r"),
            ("pressure_over_sigma", "Pi/sigma"),
            ("z", "Z"),
            ("z_mu", "Z_mu"),
        ):
            x, ex, y, ey = a[key], a[key + "_se"], b[key], b[key + "_se"]
            comb = np.hypot(ex, ey)
            print(
                f"  {label:9s} LF_DEM {x:9.4g} ± {ex:.2g}   ours {y:9.4g} ± {ey:.2g}   "
                f"diff {y - x:+.3g} = {(y - x) / comb if comb > 0 else float('nan'):+.1f} combined SE, "
                f"{100 * (y - x) / x:+.1f} %"
            )
        if args.section:
            campaign = campaign_steady(args.campaign, args.stress) if args.campaign else None
            publish_steady(args, report, a, b, campaign, argv)
    if args.json:
        args.json.write_text(json.dumps(report, indent=1, default=float) + "\n")
    return 1 if problems else 0


SETTINGS = ("stress", "control", "rate", "disp_max", "scheme", "solver")


def settings(args) -> dict:
    """The options an earlier run of ours must share to be compared again (``--ours``), with the start
    it ran from (reports written before ``--configuration`` existed ran from ``CONF``)."""
    return {
        **{key: getattr(args, key) for key in SETTINGS},
        "configuration": getattr(args, "configuration", CONF),
    }


def earlier_series(path: Path, args) -> tuple[dict, dict]:
    """Our series and cost kept by an earlier ``--json`` of the same settings."""
    try:
        report = json.loads(Path(path).read_text())
        kept, series, cost = report["settings"], report["series_ours"], report["cost_ours"]
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise SystemExit(
            f"--ours {path}: not the --json of an earlier run of ours with a strain > 0 ({exc})"
        ) from None
    kept = {"configuration": CONF, "solver": "auto", **kept}  # reports before --solver ran by auto
    if kept != settings(args):
        raise SystemExit(f"--ours {path}: made with {kept}, not the settings asked for, {settings(args)}")
    return {key: np.asarray(values, dtype=np.float64) for key, values in series.items()}, cost


STEADY_ROWS = (("viscosity", "η_r"), ("pressure_over_sigma", "Π/σ"), ("z", "Z"), ("z_mu", "Z_μ"))


def campaign_steady(paths, stress: float) -> dict:
    """Steady values of simulate.py's runs of the state point (their summaries, strain >= the run's
    steady_state_strain): the mean over the files, standard errors combined as for independent runs."""
    from rheograph.io.hdf5 import read_run_info

    infos = [read_run_info(path) for path in paths]
    out = {"runs": len(infos), "window": float(infos[0]["params"]["steady_state_strain"])}
    sources = (("viscosity", "viscosity"), ("pressure_over_sigma", "pressure"), ("z", "z"), ("z_mu", "z_mu"))
    for key, source in sources:
        scale = stress if key == "pressure_over_sigma" else 1.0
        values = np.array([info["summary"][source] for info in infos]) / scale
        errors = np.array([info["summary"][source + "_se"] for info in infos]) / scale
        out[key] = float(values.mean())
        out[key + "_se"] = float(np.sqrt((errors**2).sum()) / len(infos))
    return out


def publish_steady(args, report: dict, lfdem: dict, ours: dict, campaign: dict | None, argv) -> None:
    """The steady comparison as a published section: LF_DEM, ours from the same start and scheme, their
    difference (per cent and in combined standard errors), and simulate.py's runs where given."""
    from bench.publishing import Section, command_line, publish

    w0, w1 = report["steady"]["window"]
    what = f"σ/σ0 = {args.stress:g}" if args.control == "stress" else f"γ̇/γ̇0 = {args.rate:g}"
    header = [
        "quantity",
        f"LF_DEM (Euler, {args.lfdem_disp_max or args.disp_max:g})",
        "rheograph, same start and scheme"
        if args.scheme == "euler-lagged"
        else f"rheograph, same start, {SCHEME_LABELS[args.scheme]} {args.disp_max:g}",
        "difference",
    ]
    if campaign:
        header.append(
            f"rheograph, implicit, own start ({campaign['runs']} runs, strain ≥ {campaign['window']:g})"
        )
    rows = []
    for key, label in STEADY_ROWS:
        x, ex, y, ey = lfdem[key], lfdem[key + "_se"], ours[key], ours[key + "_se"]
        row = [
            label,
            f"{x:.4g} ± {ex:.2g}",
            f"{y:.4g} ± {ey:.2g}",
            f"{100 * (y - x) / x:+.1f} % ({(y - x) / np.hypot(ex, ey):+.1f} SE)",
        ]
        if campaign:
            row.append(f"{campaign[key]:.4g} ± {campaign[key + '_se']:.2g}")
        rows.append(row)
    cost = report["cost_ours"]
    out = Section(
        f"**The steady state, {what}**, strain {w0:g}–{w1:.2f}, the same estimator on both sides "
        "(`rheograph.analysis.steady.steady_state_summary`, 5 block standard errors), one run a side "
        "from LF_DEM's start:",
        "",
    )
    out.table(header, rows)
    if "cpu_per_strain" in cost:
        out.add(
            "",
            f"rheograph's run: {cost['cpu_per_strain']:.0f} CPU s per strain, "
            f"{cost['steps_per_strain']:.0f} steps per strain, {cost['ms_per_step']:.1f} ms per step "
            f"(strain {cost['window'][0]:.2f}–{cost['window'][1]:.2f}, one core).",
        )
    command = command_line("vs_lfdem_3d", argv)
    out.add("", f"Command: `{command}`")
    publish(
        args.section,
        out,
        True,
        page=args.page,
        record={"steady": report["steady"], "campaign": campaign, "cost_ours": cost},
        command=command,
    )


def strain_zero_check_rate_only(sim: Simulation3D, lf: dict) -> tuple[dict, list[str]]:
    res = sim.step(record=True)
    lf_sigma = np.array([sign * lf["stress_tensor"][0, k] for k, sign in LF_ST_TO_OURS])
    rate = res.shear_rate
    out = dict(
        rate_lfdem=float(lf["rate"][0]),
        rate_ours=float(rate),
        rate_rel=abs(rate - lf["rate"][0]) / abs(lf["rate"][0]),
        stress_lfdem=lf_sigma.tolist(),
        stress_ours=res.stress.tolist(),
        stress_rel=float(np.abs(res.stress - lf_sigma).max() / np.abs(lf_sigma).max()),
        pressure_lfdem=float(lf["pressure"][0]),
        pressure_ours=particle_pressure(res.stress),
    )
    problems = [f"{k} = {out[k]:.2e} > 1e-5" for k in ("rate_rel", "stress_rel") if out[k] > 1e-5]
    return out, problems


if __name__ == "__main__":
    sys.exit(main())
