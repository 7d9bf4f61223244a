"""Reading the output of LF_DEM (github.com/ryseto/LF_DEM), the C++ LF-DEM code of the seed paper, for
a 2D or 3D stress-controlled Critical Load Model run (``LF_DEM -s <σ>cl conf params``).

A 3D run (header ``Ly`` > 0) is mapped onto rheograph's 3D axes: LF_DEM shears along x with the gradient
along z and the vorticity along y, rheograph along x, y, z; (x, y, z) ours = (x, z, −y) of LF_DEM (a proper
rotation), so the box is (Lx, Lz, Ly) of LF_DEM, the Lees–Edwards offset is its shear displacement, and Π
its particle pressure (−tr σ / 3 in 3D, as rheograph's).

What is read, and from where (docs/data_format.md, "LF_DEM runs"):

* ``par_<name>.dat`` (or ``.dat.gz``): per configuration a header (``# cumulated strain``, ``# shear disp``,
  ``# shear rate``, ``# target stress``) and one row per particle (index, radius, x y z, ...).  LF_DEM's
  plane is x (flow) – z (gradient); with ``origin_zero_flow`` (its default) positions are centred, as
  rheograph's are.  The shear displacement is the x-shift of the image above, rheograph's Lees–Edwards
  offset (wrapped here).  LF_DEM prints positions with 6 significant digits: up to 5e-6 |x| of rounding,
  ~1e-4 a at the box edge of N = 400 — a tenth of a typical contact overlap, so the positions of a par
  file are an imprecise snapshot (``position_noise`` of the result gives the rounding's RMS).  The box and
  the offset are taken to full precision where the run allows: the box from the initial configuration
  copied into ``input_<name>.dat``, the offset as strain × Lz (the printed one has 6 digits too).
* the physical parameters: from LF_DEM's parameter file (``lfdem_params``), else from the copy LF_DEM
  keeps of it in ``input_<name>.dat`` beside the par file.  Keys a file omits take LF_DEM's own defaults
  (``LFDEM_DEFAULTS``, those of its source at commit 00fa7cc).  k_n and k_t as simulated are the columns
  ``kn``, ``kt`` of ``data_<name>.dat`` where it lies beside (in F_CL / a), else the parameter file's.
* targets, where ``data_<name>.dat`` lies beside: η_r = σ / γ̇ of the configuration's own header (LF_DEM's
  ``viscosity`` column is the same number), Π its ``particle pressure`` column (−tr σ / 3 with σ_yy = 0:
  rheograph's convention), and Z_μ = 2 N_frictional / N counted from the contact states (2 non-sliding,
  3 sliding) of ``int_<name>.dat`` where it lies beside, else the ``frictional contact number`` column.
"""

from __future__ import annotations

import gzip
import logging
import math
import re
import zlib
from pathlib import Path

import numpy as np

from rheograph.errors import InputError
from rheograph.io.configurations import (
    Snapshots,
    area_fraction,
    check_geometry,
    volume_fraction,
    wrap_into_box,
    wrap_into_box3d,
)

# LF_DEM's defaults (SimulationInit.cpp, setDefaultParameters) for the keys read here
LFDEM_DEFAULTS = {
    "lubrication_model": "tangential",
    "friction_model": "1",  # switched to 2 (CLM) by LF_DEM itself for a critical-load run
    "lub_max_gap": "0.5",
    "lub_reduce_parameter": "1e-3",
    "mu_static": "1",
    "mu_dynamic": "-1",  # negative: equal to mu_static
    "mu_rolling": "0",
    "kt": "0.5kn",
    "kr": "0kn",
    "disp_max": "1e-3",
}
SNAPSHOT_KEYS = {"cumulated strain": "strain", "shear disp": "shear_disp", "shear rate": "shear_rate"}
FRICTIONAL_STATES = (2, 3)  # int_*.dat contact state: 2 non-sliding frictional, 3 sliding frictional

log = logging.getLogger(__name__)


def _open_text(path: Path):
    return gzip.open(path, "rt") if path.name.endswith(".gz") else open(path)


def _sibling(par: Path, prefix: str) -> Path | None:
    """``<prefix>_<name>.dat`` (plain or .gz) beside ``par_<name>.dat[.gz]``."""
    name = par.name.removeprefix("par_").removesuffix(".gz").removesuffix(".dat")
    for candidate in (par.with_name(f"{prefix}_{name}.dat"), par.with_name(f"{prefix}_{name}.dat.gz")):
        if candidate.is_file():
            return candidate
    return None


def _file_header(lines, where) -> dict:
    """``# key value`` lines before the column list (np, VF, Lx, Ly, Lz, flow_type, units line)."""
    header = {}
    for line in lines:
        if not line.startswith("#"):
            break
        words = line[1:].split()
        if len(words) == 2 and not words[0].endswith(":"):
            header[words[0]] = words[1]
        elif line.startswith("# data in "):
            header["units"] = line.removeprefix("# data in ").strip().rstrip(".")
    for key in ("np", "Lx", "Lz"):
        if key not in header:
            raise InputError(f"{where}: no '# {key}' header line: not an LF_DEM output file")
    return header


def _par_text(path: Path) -> str:
    """The text of a par file; of a gzip file cut short, what its compressed stream holds up to the cut
    (with a warning: a copy of a finished run cut short, its unfinished configuration then left out by
    ``read_par``).  A corrupt gzip stream (a check sum that fails) is refused by name."""
    if not path.name.endswith(".gz"):
        return path.read_text()
    data, parts = path.read_bytes(), []
    while data:
        stream = zlib.decompressobj(wbits=31)  # one gzip member
        try:
            parts.append(stream.decompress(data))
        except zlib.error as exc:
            raise InputError(f"{path}: a corrupt gzip file ({exc}); is it damaged?") from exc
        if not stream.eof:
            log.warning("%s: the gzip file is cut short: configurations read up to the cut", path)
            break
        data = stream.unused_data
    try:
        return b"".join(parts).decode()
    except UnicodeDecodeError as exc:
        raise InputError(f"{path}: not an LF_DEM text file ({exc})") from exc


def read_par(path: Path) -> tuple[dict, list[dict]]:
    """(file header, snapshots): each snapshot a dict of its header values and ``radii`` (N,),
    ``positions`` (N, 2) in the x–z plane and ``xyz`` (N, 3), the three coordinates in LF_DEM's axes.

    The last configuration is left out, with a warning, where it is unfinished: fewer particle rows than
    the header's np, or a last line without its line end (a run still writing, or a copy cut short — a
    cut line may still hold five numbers, one of them cut).  Any other configuration that is not np rows
    of numbers is refused by name."""
    text = _par_text(path)
    lines = text.splitlines()
    header = _file_header(lines, path)
    try:
        n = int(header["np"])
    except ValueError as exc:
        raise InputError(f"{path}: '# np {header['np']}' is not a particle count") from exc
    cut_line = bool(text) and not text.endswith("\n")
    if cut_line:
        lines = lines[:-1]
    snapshots, current, rows = [], None, []

    def close():
        if current is None:
            return
        where = f"{path}: the configuration at strain {current.get('strain')}"
        if len(rows) != n:
            raise InputError(
                f"{where} has {len(rows)} particle rows, the header says np = {n}: the file is damaged"
            )
        try:
            if min(len(row) for row in rows) < 5:
                raise ValueError("a row has fewer than 5 columns")
            table = np.array(rows, dtype=np.float64)
        except ValueError as exc:
            raise InputError(
                f"{where} cannot be read as an LF_DEM run: its particle rows are not 5 or more numbers each "
                f"({exc})"
            ) from exc
        current["radii"] = table[:, 1]
        current["positions"] = table[:, [2, 4]]
        current["xyz"] = table[:, 2:5]
        snapshots.append(current)

    for line in lines:
        if line.startswith("# ") and " : " in line:
            key, _, value = line[2:].partition(" : ")
            key = key.strip()
            if key == "cumulated strain":
                close()
                current, rows = {}, []
            if current is not None:
                current[SNAPSHOT_KEYS.get(key, key)] = value.strip()
        elif line.strip() and not line.startswith("#") and current is not None:
            rows.append(line.split()[:5])
    if current is not None and len(rows) < n:
        log.warning(
            "%s: its last configuration (strain %s) is unfinished (%d of %d particle rows whole: a run "
            "still writing, or a copy cut short): left out",
            path,
            current.get("strain"),
            len(rows),
            n,
        )
        current = None
    close()
    if not snapshots:
        raise InputError(f"{path}: no complete configuration in this LF_DEM par file")
    return header, snapshots


def read_parameter_text(text: str) -> dict:
    """``key = value;`` lines of an LF_DEM parameter file (C comments ignored) as strings."""
    text = re.sub(r"/\*.*?\*/", "", text, flags=re.S)
    values = {}
    for statement in text.split(";"):
        statement = statement.split("//")[0].strip()
        if "=" in statement:
            key, value = (part.strip() for part in statement.split("=", 1))
            values[key] = value
    return values


def _parameters_from_input_record(path: Path) -> dict | None:
    """LF_DEM copies its parameter file into ``input_<name>.dat`` after a '***** File <name> *****' line."""
    record = _sibling(path, "input")
    if record is None:
        return None
    with _open_text(record) as fh:
        sections = re.split(r"^\*+ File (\S+) \*+$", fh.read(), flags=re.M)
    # sections: [preamble, name1, text1, name2, text2, ...]: the configuration comes first, then parameters
    for text in sections[2::2]:
        values = read_parameter_text(text)
        if any(key in values for key in ("kn", "mu_static", "lub_max_gap", "friction_model")):
            return values
    return None


def _exact_box(path: Path) -> tuple[float, float, float] | None:
    """(Lx, Ly, Lz) in LF_DEM's axes to full precision from the initial configuration's header that
    LF_DEM copies into ``input_<name>.dat`` (``# np1 np2 vf lx ly lz ...``); the par file's header has 6
    digits only."""
    record = _sibling(path, "input")
    if record is None:
        return None
    with _open_text(record) as fh:
        lines = fh.read().splitlines()
    for k, line in enumerate(lines[:-1]):
        keys = line[1:].split()
        if line.startswith("#") and "lx" in keys and "lz" in keys:
            values = lines[k + 1][1:].split()
            if len(values) == len(keys):
                return tuple(float(values[keys.index(key)]) for key in ("lx", "ly", "lz"))
    return None


def _stiffness(value: str, kn: float | None, stress: float, key: str, where) -> float:
    """A stiffness of the parameter file in F_CL / a: units ``s`` (the imposed stress: LF_DEM's k_n =
    value · σ a), ``cl`` (critical load) or ``kn`` (times k_n)."""
    match = re.fullmatch(r"([-+0-9.eE]+)\s*([a-z]*)", value)
    if not match:
        raise InputError(f"{where}: cannot read {key} = {value}")
    number, unit = float(match[1]), match[2]
    if unit == "kn" and kn is not None:
        return number * kn
    if unit == "s":  # in units of the stress scale: sigma a^2 / a = (sigma/sigma0) F_CL / (6 pi a)
        return number * stress / (6.0 * math.pi)
    if unit == "cl":
        return number
    raise InputError(f"{where}: {key} = {value}: unit '{unit}' not understood (s, cl or kn)")


def lfdem_physical_params(values: dict, stress: float, where, kn_kt=None) -> tuple[dict, dict]:
    """(rheograph's physical parameters, numerics) from LF_DEM parameter strings ``values`` (LF_DEM's
    defaults for omitted keys); ``kn_kt``: (k_n, k_t) [F_CL / a] as simulated, where known."""
    v = {**LFDEM_DEFAULTS, **values}
    problems = []
    if v["lubrication_model"] != "tangential":
        problems.append(f"lubrication_model = {v['lubrication_model']} (rheograph: tangential)")
    if v["friction_model"] not in ("1", "2"):  # 1 is switched to 2 by LF_DEM in a critical-load run
        problems.append(f"friction_model = {v['friction_model']} (rheograph: the CLM, 2)")
    mu, mu_dynamic = float(v["mu_static"]), float(v["mu_dynamic"])
    if mu_dynamic >= 0 and not math.isclose(mu_dynamic, mu):
        problems.append(f"mu_dynamic = {mu_dynamic:g} differs from mu_static = {mu:g} (rheograph: one mu)")
    if float(v["mu_rolling"]) != 0 or not v["kr"].startswith("0"):
        problems.append("rolling friction (mu_rolling, kr) is on (rheograph: none)")
    if problems:
        raise InputError(
            f"{where}: an LF_DEM run that rheograph's model does not describe: " + "; ".join(problems)
        )
    if "kn" in v:  # exact where the file gives it; the data columns carry 6 digits
        kn = _stiffness(v["kn"], None, stress, "kn", where)
        kt = _stiffness(v["kt"], kn, stress, "kt", where)
        if kn_kt is not None and not (
            math.isclose(kn, kn_kt[0], rel_tol=1e-5)
            and math.isclose(kt, kn_kt[1], rel_tol=1e-5, abs_tol=1e-9)
        ):
            raise InputError(
                f"{where}: the parameters give k_n = {kn:.6g}, k_t = {kt:.6g} F_CL/a, but the run's data "
                "file "
                f"records {kn_kt[0]:.6g}, {kn_kt[1]:.6g}: is this the parameter file of this run?"
            )
    elif kn_kt is not None:
        kn, kt = kn_kt
    else:
        raise InputError(f"{where}: no kn in LF_DEM's parameters and no data_*.dat beside with its value")
    params = {
        "mu": mu,
        "kn_coefficient": kn * 6.0 * math.pi / stress,
        "kt_ratio": kt / kn,
        "delta": float(v["lub_reduce_parameter"]),
        "lub_max_gap": float(v["lub_max_gap"]),
        "critical_load": 1.0,
    }
    numerics = {"disp_max": float(v["disp_max"])}
    return params, numerics


def _data_table(path: Path) -> tuple[dict, np.ndarray]:
    """Column index (0-based) by name and the rows of a data_*.dat."""
    columns, rows = {}, []
    with _open_text(path) as fh:
        for line in fh:
            match = re.match(r"#(\d+)(?:-\d+)?: (.*)", line)
            if match:
                columns[match[2].strip()] = int(match[1]) - 1
            elif line.strip() and not line.startswith("#"):
                rows.append(line.split())
    width = min(len(r) for r in rows) if rows else 0
    return columns, np.array([r[:width] for r in rows], dtype=np.float64).reshape(len(rows), width)


def _frictional_counts(path: Path, n_snap: int) -> list[int]:
    """Frictional contacts (states 2, 3) per configuration of an int_*.dat."""
    counts = []
    with _open_text(path) as fh:
        for line in fh:
            if line.startswith("# cumulated strain"):
                counts.append(0)
            elif counts and line.strip() and not line.startswith("#"):
                if int(line.split()[2]) in FRICTIONAL_STATES:
                    counts[-1] += 1
    return counts[:n_snap]


def read_lfdem(path: str | Path, lfdem_params: str | Path | None = None) -> Snapshots:
    """The configurations of an LF_DEM ``par_*.dat[.gz]`` with its parameters and, where the files lie
    beside, its targets (module docstring)."""
    path = Path(path)
    where = str(path)
    header, blocks = read_par(path)
    if header.get("flow_type", "shear") != "shear":
        raise InputError(f"{where}: not a simple-shear LF_DEM run (flow_type {header.get('flow_type')})")
    # a 3D run has a vorticity edge Ly; its axes map onto ours by (x, y, z) = (x, z, -y) of LF_DEM
    three_d = float(header.get("Ly", 0)) != 0
    if header.get("units", "critical_load units") != "critical_load units":
        raise InputError(
            f"{where}: data in {header['units']}; rheograph reads critical-load units (LF_DEM -s <σ>cl)"
        )
    if "target stress" not in blocks[0]:
        raise InputError(f"{where}: no '# target stress' line: not a stress-controlled LF_DEM run")
    stresses = {float(b["target stress"]) for b in blocks}
    if len(stresses) != 1:
        raise InputError(f"{where}: the target stress changes during the run ({sorted(stresses)})")
    stress = stresses.pop()
    lx, ly = float(header["Lx"]), float(header["Lz"])
    lz = float(header["Ly"]) if three_d else None
    exact = _exact_box(path)
    if (
        exact is not None
        and math.isclose(exact[0], lx, rel_tol=1e-5)
        and math.isclose(exact[2], ly, rel_tol=1e-5)
        and (lz is None or math.isclose(exact[1], lz, rel_tol=1e-5))
    ):
        lx, ly = exact[0], exact[2]
        lz = exact[1] if three_d else None
    radii = blocks[0]["radii"]
    phi = area_fraction(radii, lx, ly) if lz is None else volume_fraction(radii, lx, ly, lz)
    check_geometry(where, radii, lx, ly, float(header.get("VF", phi)), lz)

    if lfdem_params is not None:
        try:
            values = read_parameter_text(Path(lfdem_params).read_text())
        except OSError as exc:
            raise InputError(f"--lfdem-params {lfdem_params}: cannot be read ({exc})") from exc
    else:
        values = _parameters_from_input_record(path)
        if values is None:
            raise InputError(
                f"{where}: LF_DEM's parameters are needed (mu, lubrication, stiffness): give its parameter "
                "file (predict.py --lfdem-params FILE, data.lfdem_params=FILE) or keep input_*.dat beside"
            )
    data_file = _sibling(path, "data")
    kn_kt, data = None, None
    strain = np.array([float(b["strain"]) for b in blocks])
    if data_file is not None:
        columns, table = _data_table(data_file)
        data = (columns, table)
        if "kn" in columns and "kt" in columns and table.size:
            kn_kt = (float(table[-1, columns["kn"]]), float(table[-1, columns["kt"]]))
    params, numerics = lfdem_physical_params(values, stress, where, kn_kt)
    params["size_ratio"] = round(float(radii.max() / radii.min()), 6)

    # the offset is gamma Ly modulo Lx; computed from the (exact) output strain where it agrees with the
    # printed 6-digit shear displacement, which LF_DEM wraps into [0, Lx)
    printed = np.array([float(b["shear_disp"]) for b in blocks])
    from_strain = strain * ly
    gap = np.abs((from_strain - printed + 0.5 * lx) % lx - 0.5 * lx)
    offsets = np.where(gap < 1e-3, from_strain, printed)
    offsets = offsets - lx * np.floor(offsets / lx + 0.5)
    if not (np.isfinite(offsets).all() and all(np.isfinite(b["xyz"]).all() for b in blocks)):
        raise InputError(f"{where}: positions or shear displacements that are not finite numbers (nan, inf)")
    if three_d:
        positions = np.stack(
            [
                wrap_into_box3d(b["xyz"][:, [0, 2, 1]] * [1.0, 1.0, -1.0], lx, ly, lz, o)
                for b, o in zip(blocks, offsets)
            ]
        )
    else:
        positions = np.stack([wrap_into_box(b["positions"], lx, ly, o) for b, o in zip(blocks, offsets)])
    shear_rate = np.array([float(b["shear_rate"]) for b in blocks])
    targets = np.full((len(blocks), 3), np.nan)
    if data is not None:
        columns, table = data
        row_strain = table[:, columns["cumulated shear strain"]]
        rows = np.array([int(np.argmin(np.abs(row_strain - g))) for g in strain])
        matched = np.abs(row_strain[rows] - strain) <= 1e-5 * np.maximum(1.0, np.abs(strain))
        with np.errstate(divide="ignore"):
            targets[:, 0] = np.where(matched, stress / shear_rate, np.nan)
        targets[:, 1] = np.where(matched, table[rows, columns["particle pressure"]], np.nan)
        targets[:, 2] = np.where(matched, table[rows, columns["frictional contact number"]], np.nan)
    int_file = _sibling(path, "int")
    if int_file is not None:
        counts = _frictional_counts(int_file, len(blocks))
        targets[: len(counts), 2] = 2.0 * np.array(counts) / radii.size
    coordinates = "xyz" if three_d else "positions"
    # RMS of rounding to 6 significant digits: uniform over +-0.5 unit of the last digit of each coordinate
    last_digit = 10.0 ** (
        np.floor(np.log10(np.maximum(np.abs(np.stack([b[coordinates] for b in blocks])), 1e-12))) - 5
    )
    rounding = float(np.sqrt(np.mean(last_digit**2) / 12.0))
    return Snapshots(
        source=where,
        kind="lfdem",
        positions=positions,
        radii=radii,
        lx=lx,
        ly=ly,
        le_offset=offsets,
        strain=strain,
        stress=stress,
        phi=phi,
        params=params,
        targets=targets,
        jammed=np.zeros(len(blocks), dtype=bool),
        numerics=numerics,
        position_noise=rounding,
        lz=lz,
    )


def read_lfdem_data(path) -> dict:
    """Columns of an LF_DEM ``data_*.dat`` time series (see data/lfdem_reference/README.md)."""
    table = np.loadtxt(path, comments="#")
    return {
        "time": table[:, 0],
        "strain": table[:, 1],
        "shear_rate": table[:, 2],
        "viscosity": table[:, 3],
        "pressure": table[:, 11],
        "z": table[:, 17],
        "z_mu": table[:, 18],
        "dt": table[:, 22],
    }
