"""Steady-state statistics shared by the simulator's summaries, flow curves and reference comparisons."""

from __future__ import annotations

import numpy as np

from rheograph.errors import InputError


def steady_state_summary(
    strain: np.ndarray,
    time: np.ndarray,
    pressure: np.ndarray,
    z_mu: np.ndarray,
    z: np.ndarray,
    stress: float,
    strain_min: float,
    n_blocks: int = 5,
    viscosity: np.ndarray | None = None,
    series: dict | None = None,
) -> dict:
    """Strain-weighted means over the rows with strain >= strain_min of a time series.

    eta_r = sigma * (time elapsed) / (strain accumulated): the time average of the shear rate gives the
    steady viscosity (equal to the strain-weighted mean of the instantaneous sigma/shear_rate).  Under
    rate control there is no imposed sigma: ``viscosity``, the instantaneous sigma_xy / (eta0 rate)
    series, is averaged with the strain weights instead.  ``series``: further columns averaged the same
    way (e.g. the 3D normal stress differences n1, n2).
    Standard errors come from ``n_blocks`` consecutive blocks of equal row count.
    Returns NaN entries (never fabricated numbers) when the window holds fewer than 2 rows per block.
    """
    series = series or {}
    keep = strain >= strain_min
    out = {"strain_window": float(strain[keep][-1] - strain[keep][0]) if keep.sum() > 1 else 0.0}
    names = ("viscosity", "pressure", "z_mu", "z", *series)
    if keep.sum() < 2 * n_blocks:
        for name in names:
            out[name] = out[name + "_se"] = float("nan")
        out["n_rows"] = int(keep.sum())
        return out
    s, t = strain[keep], time[keep]
    blocks = np.array_split(np.arange(s.shape[0]), n_blocks)

    def eta(idx):
        return stress * (t[idx[-1]] - t[idx[0]]) / (s[idx[-1]] - s[idx[0]])

    # strain weights: each row stands for the strain to the next row, so rows written while the flow
    # stalled (time-triggered, see rheograph.runs.runner) do not outweigh the strain-sampled ones
    w = np.clip(np.diff(s, append=s[-1] + np.median(np.diff(s))), 0.0, None)
    if w.sum() <= 0:
        w = np.ones_like(s)
    averaged = {"pressure": pressure, "z_mu": z_mu, "z": z, **series}
    if viscosity is None:
        out["viscosity"] = float(stress * (t[-1] - t[0]) / (s[-1] - s[0]))
        out["viscosity_se"] = float(np.std([eta(b) for b in blocks], ddof=1) / np.sqrt(n_blocks))
    else:
        averaged["viscosity"] = viscosity
    for name, values in averaged.items():
        x = values[keep]
        out[name] = float(np.average(x, weights=w))
        block_means = [np.average(x[b], weights=w[b]) if w[b].sum() > 0 else x[b].mean() for b in blocks]
        out[name + "_se"] = float(np.std(block_means, ddof=1) / np.sqrt(n_blocks))
    out["n_rows"] = int(keep.sum())
    return out


def steady_extras(params: dict, ts: dict) -> dict:
    """The keyword arguments of ``steady_state_summary`` for a run of stored parameters ``params`` (a
    file's ``params``) with time series ``ts``: in 3D (``dim`` 3) its normal stress differences, and under
    rate control its viscosity series; none for a 2D run."""
    extras = {}
    if params.get("dim", 2) == 3:
        extras["series"] = {"n1": ts["n1"], "n2": ts["n2"]}
    if params.get("control", "stress") == "rate":
        extras["viscosity"] = ts["viscosity"]
    return extras


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


def stall_start(strain, slow) -> float | None:
    """The strain from which every row of a time series is flagged ``slow`` (its interval slower than the
    jam viscosity), or None when the last row is not: a run stalling into arrest, before the jam detector's
    window is full.  strain, slow: (T,)."""
    slow = np.asarray(slow, dtype=bool)
    if slow.size == 0 or not slow[-1]:
        return None
    first = 0 if slow.all() else slow.size - int(np.argmin(slow[::-1]))
    return float(np.asarray(strain)[first])


def ensemble_transient(
    runs: list[tuple[np.ndarray, np.ndarray, object]],
    counted_from: float,
    block: float = 0.5,
    alpha: float = 0.05,
) -> dict:
    """Start-up transient of the runs of one (N, φ), resolved on their ensemble.

    One run's block means are too noisy to resolve a slow drift of a few per cent; the runs of an (N, φ)
    together can -- but the drift's sign may depend on the state point, so runs are compared within their
    state point and never averaged across state points.  Per run, the mean of ``values`` over each
    ``block``-strain block before its reference window (the second half of its strain beyond
    ``counted_from``, rounded down to a whole block) minus the window's mean, in units of the run's
    standard deviation there.  Each block is tested two ways, the smaller p value doubled: an F test
    for any state point's mean offset differing from 0 (sum over state points of n_g x mean_g^2 over
    their count, against the scatter between runs of one state point, pooled), and a t test for a drift
    of one sign (the state points' mean offsets, k - 1 degrees of freedom), which the F test, spread over
    k state points, resolves poorly.  Significant below ``alpha`` / (number of blocks) -- Bonferroni
    bounds, so that stationary runs report a transient in at most ``alpha`` of ensembles.

    runs: (strain (T,), values (T,), state point key) per run; each run's rows are weighted equally.
    Returns ``block_start`` (B,) and ``p_value`` (B,) (NaN where it cannot be tested), ``transient``: the
    end of the last significant block (0 when none; ``ceiling``, the earliest reference window, is its
    largest value: ``at_ceiling`` says the drift may continue into the window), and the bias that counting
    each run from ``counted_from`` instead of from the transient adds to its mean (in ``values``' units):
    ``bias_mean`` over runs, ``bias_largest`` the largest |mean over a state point's runs|, signed, at
    state point ``bias_largest_at``; ``n_runs`` used.  NaN entries when fewer than 2 state points hold 2
    runs that reach a reference window (no within-state-point scatter to test against)."""
    from scipy.stats import f as f_distribution
    from scipy.stats import t as t_distribution

    if not (np.isfinite(block) and block > 0):
        raise InputError(f"block={block!r} is invalid: allowed a positive strain")
    if not (np.isfinite(counted_from) and counted_from >= 0):
        raise InputError(f"counted_from={counted_from!r} is invalid: allowed a strain >= 0")
    usable = []
    for strain, values, key in runs:
        strain, values = np.asarray(strain, dtype=np.float64), np.asarray(values, dtype=np.float64)
        if strain.size == 0:
            continue
        reference_from = np.floor(0.5 * (counted_from + strain.max()) / block + 1e-9) * block
        window = values[strain >= reference_from]
        if reference_from < block or strain.max() - reference_from < block or window.std() == 0:
            continue
        usable.append((strain, values, key, reference_from, window.mean(), window.std()))
    nan = float("nan")
    empty = dict(block_start=np.zeros(0), p_value=np.zeros(0), transient=nan, ceiling=nan, at_ceiling=False,
                 bias_mean=nan, bias_largest=nan, bias_largest_at=None, n_runs=len(usable))  # fmt: skip
    keys = [u[2] for u in usable]
    replicated = {k for k in keys if keys.count(k) >= 2}
    if len(replicated) < 2:
        return empty
    ceiling = min(u[3] for u in usable)
    starts = np.arange(0.0, ceiling - 1e-9, block)
    offsets = np.full((len(usable), starts.size), nan)
    for i, (strain, values, _, _, centre, spread) in enumerate(usable):
        for b, s in enumerate(starts):
            inside = (strain >= s) & (strain < s + block)
            if inside.any():
                offsets[i, b] = (values[inside].mean() - centre) / spread
    p_value = np.full(starts.size, nan)
    for b in range(starts.size):
        groups = [offsets[[i for i, k in enumerate(keys) if k == key], b] for key in dict.fromkeys(keys)]
        groups = [g[np.isfinite(g)] for g in groups]
        groups = [g for g in groups if g.size]
        dof = sum(g.size - 1 for g in groups)
        if dof == 0:
            continue
        within = sum(((g - g.mean()) ** 2).sum() for g in groups) / dof
        between = sum(g.size * g.mean() ** 2 for g in groups) / len(groups)
        if within == 0:
            continue
        p_any = f_distribution.sf(between / within, len(groups), dof)
        # a drift of one sign at every state point: t test on the state points' means (k - 1 dof)
        means = np.array([g.mean() for g in groups])
        spread = means.std(ddof=1) / np.sqrt(means.size)
        p_common = 2 * t_distribution.sf(abs(means.mean()) / spread, means.size - 1) if spread > 0 else nan
        p_value[b] = min(1.0, 2 * np.nanmin([p_any, p_common]))
    significant = np.flatnonzero(p_value < alpha / max(starts.size, 1))
    transient = float(starts[significant[-1]] + block) if significant.size else 0.0
    start = max(transient, counted_from)
    bias = np.array([v[s >= counted_from].mean() - v[s >= start].mean() for s, v, *_ in usable])
    by_point = {key: bias[[i for i, k in enumerate(keys) if k == key]].mean() for key in dict.fromkeys(keys)}
    largest_at = max(by_point, key=lambda key: abs(by_point[key]))
    return dict(
        block_start=starts,
        p_value=p_value,
        transient=transient,
        ceiling=float(ceiling),
        at_ceiling=bool(transient >= ceiling - 1e-9),
        bias_mean=float(bias.mean()),
        bias_largest=float(by_point[largest_at]),
        bias_largest_at=largest_at,
        n_runs=len(usable),
    )
