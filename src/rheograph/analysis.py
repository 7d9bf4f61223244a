"""Steady-state statistics shared by the simulator's summaries, flow curves and reference comparisons."""

from __future__ import annotations

import numpy as np


def steady_state_summary(
    strain: np.ndarray,
    time: np.ndarray,
    pressure: np.ndarray,
    z_mu: np.ndarray,
    z: np.ndarray,
    stress: float,
    strain_min: float,
    n_blocks: int = 5,
) -> dict:
    """Strain-weighted means over the rows with strain >= strain_min of a time series.

    eta_r = sigma * (time elapsed) / (strain accumulated): the time average of the shear rate gives the
    steady viscosity (equal to the strain-weighted mean of the instantaneous sigma/shear_rate).
    Standard errors come from ``n_blocks`` consecutive blocks of equal row count.
    Returns NaN entries (never fabricated numbers) when the window holds fewer than 2 rows per block.
    """
    keep = strain >= strain_min
    out = {"strain_window": float(strain[keep][-1] - strain[keep][0]) if keep.sum() > 1 else 0.0}
    names = ("viscosity", "pressure", "z_mu", "z")
    if keep.sum() < 2 * n_blocks:
        for name in names:
            out[name] = out[name + "_se"] = float("nan")
        out["n_rows"] = int(keep.sum())
        return out
    s, t = strain[keep], time[keep]
    blocks = np.array_split(np.arange(s.shape[0]), n_blocks)

    def eta(idx):
        return stress * (t[idx[-1]] - t[idx[0]]) / (s[idx[-1]] - s[idx[0]])

    out["viscosity"] = float(stress * (t[-1] - t[0]) / (s[-1] - s[0]))
    out["viscosity_se"] = float(np.std([eta(b) for b in blocks], ddof=1) / np.sqrt(n_blocks))
    # strain weights: each row stands for the strain to the next row, so rows written while the flow
    # stalled (time-triggered, see rheograph.runner) do not outweigh the strain-sampled ones
    w = np.clip(np.diff(s, append=s[-1] + np.median(np.diff(s))), 0.0, None)
    if w.sum() <= 0:
        w = np.ones_like(s)
    for name, series in (("pressure", pressure), ("z_mu", z_mu), ("z", z)):
        x = series[keep]
        out[name] = float(np.average(x, weights=w))
        block_means = [np.average(x[b], weights=w[b]) if w[b].sum() > 0 else x[b].mean() for b in blocks]
        out[name + "_se"] = float(np.std(block_means, ddof=1) / np.sqrt(n_blocks))
    out["n_rows"] = int(keep.sum())
    return out


def read_lfdem_data(path) -> dict:
    """Columns of an LF_DEM ``data_*.dat`` time series (see shared/reference/README.md)."""
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


def decorrelation_strain(values, strain_step: float) -> float:
    """Strain over which the normalised autocorrelation of an evenly sampled series first drops below
    1/e (the integral-free, noise-robust choice), linearly interpolated between samples.

    ``values`` (R,) sampled every ``strain_step``; returns NaN for fewer than 8 samples or a constant
    series, and the whole span when the correlation never drops below 1/e (not decorrelated)."""
    x = np.asarray(values, dtype=np.float64)
    x = x[np.isfinite(x)]
    if x.size < 8 or np.ptp(x) == 0.0:
        return float("nan")
    x = x - x.mean()
    n = x.size
    spectrum = np.fft.rfft(x, 2 * n)
    acf = np.fft.irfft(spectrum * np.conj(spectrum))[:n]
    acf /= acf[0]
    below = np.flatnonzero(acf < np.exp(-1.0))
    if below.size == 0:
        return float(n * strain_step)
    k = int(below[0])
    # interpolate between lag k-1 (above 1/e) and k (below)
    frac = (acf[k - 1] - np.exp(-1.0)) / (acf[k - 1] - acf[k])
    return float((k - 1 + frac) * strain_step)


def transient_strain(strain, values, steady_from: float, block: float = 0.1) -> float:
    """Start-up transient: the first strain from which every ``block``-strain block mean of ``values``
    stays within 2 standard deviations of the block means of the steady window (strain >= steady_from).

    Returns NaN when the steady window holds fewer than 3 blocks."""
    strain, values = np.asarray(strain, dtype=np.float64), np.asarray(values, dtype=np.float64)
    edges = np.arange(0.0, strain.max() + block, block)
    idx = np.digitize(strain, edges) - 1
    means = np.array([values[idx == b].mean() if np.any(idx == b) else np.nan for b in range(edges.size)])
    steady = means[edges >= steady_from]
    steady = steady[np.isfinite(steady)]
    if steady.size < 3:
        return float("nan")
    centre, spread = steady.mean(), 2.0 * steady.std(ddof=1)
    outside = np.flatnonzero(np.isfinite(means) & (np.abs(means - centre) > spread) & (edges < steady_from))
    return float(edges[outside[-1]] + block) if outside.size else 0.0


def jammed_snapshots(status: str, snapshot_strain, series_strain, jam_intervals: int) -> np.ndarray:
    """(S,) bool: the snapshots of a run taken after its flow stopped.

    A run ends ``jammed`` when over its last ``jam_intervals`` output intervals -- between its last
    ``jam_intervals`` + 1 rows -- the flow was together slower than the jam viscosity (rheograph.runner);
    the snapshots from the first row of that window on show the arrested packing (its Π and Z_μ are
    targets, its η_r is not), the earlier ones a flowing suspension.  All False for a run that did not
    jam."""
    snapshot_strain = np.asarray(snapshot_strain, dtype=np.float64)
    series_strain = np.asarray(series_strain, dtype=np.float64)
    if status != "jammed" or series_strain.size == 0:
        return np.zeros(snapshot_strain.size, dtype=bool)
    onset = series_strain[max(series_strain.size - 1 - int(jam_intervals), 0)]
    return snapshot_strain >= onset


def ensemble_transient(
    runs: list[tuple[np.ndarray, np.ndarray]],
    reference_from: float,
    counted_from: float,
    block: float = 0.5,
) -> dict:
    """Start-up transient of a set of runs at one state family, measured on their average.

    One run's block means are too noisy to resolve a slow relaxation of a few per cent; averaged over the
    runs of an (N, φ) they are not.  Per run, the means of ``values`` over ``block``-strain blocks below
    ``reference_from`` minus the run's mean over strain >= ``reference_from``; averaged over the runs
    (each run counted once), with the standard error over runs.

    runs: (strain, values) per run, each (T,) with rows at a fixed strain interval (the time series).
    Returns ``block_start`` (B,), ``offset`` and ``offset_se`` (B,) -- NaN where fewer than 2 runs
    reach a block --, ``transient``: the end of the last block whose offset exceeds 2 standard
    errors (0 when none does; ``reference_from`` is its ceiling), and ``bias``/``bias_se``: the mean
    over runs of (mean over strain >= ``counted_from``) - (mean over strain >= ``transient``), i.e. what
    counting a run from ``counted_from`` adds to its steady mean.  NaN entries when no run reaches
    ``reference_from`` + ``block``."""
    starts = np.arange(0.0, reference_from - 1e-9, block)
    offsets, biases = [], []
    for strain, values in runs:
        strain, values = np.asarray(strain, dtype=np.float64), np.asarray(values, dtype=np.float64)
        if strain.size == 0 or strain.max() < reference_from + block:
            continue
        reference = values[strain >= reference_from].mean()
        offsets.append(
            [
                values[(strain >= s) & (strain < s + block)].mean() - reference
                if np.any((strain >= s) & (strain < s + block))
                else np.nan
                for s in starts
            ]
        )
        biases.append((strain, values))
    nan = float("nan")
    if not offsets:
        return dict(
            block_start=starts,
            offset=starts * nan,
            offset_se=starts * nan,
            transient=nan,
            bias=nan,
            bias_se=nan,
        )
    table = np.array(offsets)
    counts = np.isfinite(table).sum(axis=0)
    offset = np.where(counts >= 2, np.nanmean(table, axis=0), nan) if table.size else table
    with np.errstate(invalid="ignore", divide="ignore"):
        offset_se = np.where(counts >= 2, np.nanstd(table, axis=0, ddof=1) / np.sqrt(counts), nan)
    significant = np.flatnonzero(np.isfinite(offset) & (np.abs(offset) > 2.0 * offset_se))
    transient = float(starts[significant[-1]] + block) if significant.size else 0.0
    bias = np.array(
        [v[s >= counted_from].mean() - v[s >= max(transient, counted_from)].mean() for s, v in biases]
    )
    bias_se = float(bias.std(ddof=1) / np.sqrt(bias.size)) if bias.size > 1 else nan
    return dict(
        block_start=starts,
        offset=offset,
        offset_se=offset_se,
        transient=transient,
        bias=float(bias.mean()),
        bias_se=bias_se,
    )
