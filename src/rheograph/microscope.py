"""From a microscope frame to a snapshot the surrogates read (2D): render a snapshot as a fluorescence
frame, locate its particles with trackpy, sort them into the two species, and build the ``Snapshots``
that ``Surrogate.predict_snapshots`` takes; and an (x, y, r) table in µm converted to units of a.

    frame = render_frame(positions, radii, (lx, ly), pixel_size=0.15, psf_sigma=0.2, photons=100,
                         background=10, rng=np.random.default_rng(0), le_offset=le, dyed_fraction=0.5)
    tracked = track_frame(frame, pixel_size=0.15, diameter_px=13, le_offset=le)
    snaps = snapshot_from_frame(tracked, le_offset=le, stress=10, phi=0.76, params=PARAMS,
                                position_noise=tracked.precision)

The field of view is the periodic box (Lx, Ly) = the frame's (columns, rows) × pixel size, with the
Lees–Edwards offset given by the user: the image above the box is the box shifted by +le_offset in x.
Lengths in units of the small radius a unless named otherwise (pixels: ``_px``).

Uniformly dyed particles that touch (a dense monolayer) merge into one bright field in the image, which
centroid tracking cannot take apart (bench/microscope.py at φ = 0.76: errors of 0.19 a per coordinate,
over half the particles missed, no two size groups); particles with a fluorescent core and a clear shell
(``dyed_fraction`` 0.5, e.g. core–shell colloids) stay separate blobs and track to 0.009 a, none lost.

trackpy is an optional dependency (``pip install rheograph[microscope]``), imported only by
``track_frame``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from rheograph.errors import InputError
from rheograph.io.configurations import Snapshots, area_fraction, wrap_into_box
from rheograph.io.snapshots import snapshots_from_values

# sub-pixels per pixel side when the discs are drawn: the partial coverage of edge pixels to 1/16
SUPERSAMPLE = 4
# tolerance of the stated area fraction against the one the radii and box give: the readers'
# (rheograph.io.configurations.check_geometry); one small particle in N = 400 at φ 0.76 is 1.3e-3
PHI_TOLERANCE = 1e-3
# how far a measured radius may lie from its species' nominal one (relative) before a table is refused:
# beyond the 4-10 % spread of real colloids, short of the 40 % between the two species
SPECIES_SPREAD = 0.2


# ---- rendering ---------------------------------------------------------------------------------------
def _frame_shape(lx: float, ly: float, pixel_size: float) -> tuple[int, int]:
    """(rows, columns) of a frame whose field of view is the box: a whole number of pixels each way."""
    if not (math.isfinite(pixel_size) and pixel_size > 0):
        raise InputError(f"pixel_size = {pixel_size}: must be a positive length [a per pixel]")
    shape = []
    for name, length in (("Ly", ly), ("Lx", lx)):
        count = round(length / pixel_size)
        if count < 1 or not math.isclose(count * pixel_size, length, rel_tol=1e-6):
            raise InputError(
                f"pixel_size = {pixel_size:g}: the field of view is the box, so {name} = {length:g} a must "
                f"be a whole number of pixels; use pixel_size = {length / max(count, 1):.10g}"
            )
        shape.append(count)
    return shape[0], shape[1]


def _periodic_images(positions, lx: float, ly: float, le_offset: float) -> tuple[np.ndarray, np.ndarray]:
    """Centres (9N, 2) [a] of every particle and its eight nearest periodic images (the image above a
    particle is shifted by +le_offset in x), and which particle each is (9N,)."""
    shifts = [(i * lx + j * le_offset, j * ly) for j in (-1, 0, 1) for i in (-1, 0, 1)]
    centres = np.concatenate([positions + np.array(s) for s in shifts])
    return centres, np.tile(np.arange(len(positions)), len(shifts))


def _disc_coverage(centres, radii, shape, pixel_size: float, margin: int, origin) -> np.ndarray:
    """Fraction of each pixel (rows + 2 margin, cols + 2 margin) covered by discs, drawn on
    ``SUPERSAMPLE``² sub-pixels; ``origin`` [a]: the (x, y) of the primary frame's lower-left corner."""
    rows, cols = shape[0] + 2 * margin, shape[1] + 2 * margin
    sub = pixel_size / SUPERSAMPLE
    canvas = np.zeros((rows * SUPERSAMPLE, cols * SUPERSAMPLE))
    x0, y0 = origin[0] - margin * pixel_size, origin[1] - margin * pixel_size
    for (cx, cy), r in zip(centres, radii):
        lo_i, hi_i = int((cy - r - y0) / sub), int(np.ceil((cy + r - y0) / sub)) + 1
        lo_j, hi_j = int((cx - r - x0) / sub), int(np.ceil((cx + r - x0) / sub)) + 1
        lo_i, lo_j = max(lo_i, 0), max(lo_j, 0)
        hi_i, hi_j = min(hi_i, canvas.shape[0]), min(hi_j, canvas.shape[1])
        if lo_i >= hi_i or lo_j >= hi_j:  # an image wholly outside the padded frame
            continue
        ys = y0 + (np.arange(lo_i, hi_i) + 0.5) * sub
        xs = x0 + (np.arange(lo_j, hi_j) + 0.5) * sub
        inside = (xs[None, :] - cx) ** 2 + (ys[:, None] - cy) ** 2 < r * r
        canvas[lo_i:hi_i, lo_j:hi_j] = np.maximum(canvas[lo_i:hi_i, lo_j:hi_j], inside)
    return canvas.reshape(rows, SUPERSAMPLE, cols, SUPERSAMPLE).mean(axis=(1, 3))


def render_frame(
    positions,
    radii,
    box,
    pixel_size: float,
    psf_sigma: float,
    photons: float,
    background: float,
    rng: np.random.Generator,
    le_offset: float = 0.0,
    dyed_fraction: float = 1.0,
) -> np.ndarray:
    """A fluorescence frame (rows, columns) of photon counts of a 2D snapshot: discs of radius
    ``dyed_fraction`` × the particle radii (1: uniformly dyed; < 1: a fluorescent core in a clear
    shell), uniformly bright, blurred by a Gaussian point-spread function of ``psf_sigma`` [a], with
    Poisson shot noise of mean ``photons`` per pixel inside a disc plus ``background`` per pixel.

    ``positions`` (N, 2) [a], ``radii`` (N,) [a], ``box`` = (Lx, Ly) [a], ``pixel_size`` [a per pixel]
    (the box a whole number of pixels: the field of view is the box), ``le_offset`` [a]: discs crossing
    the box's edges appear on both sides, shifted by the Lees–Edwards offset across the y-boundary.
    Row i, column j is the pixel centred at (-Lx/2 + (j + 1/2) px, -Ly/2 + (i + 1/2) px)."""
    lx, ly = (float(v) for v in box)
    shape = _frame_shape(lx, ly, pixel_size)
    positions = wrap_into_box(np.asarray(positions, dtype=np.float64), lx, ly, le_offset)
    radii = np.asarray(radii, dtype=np.float64)
    if not 0 < dyed_fraction <= 1:
        raise InputError(f"dyed_fraction = {dyed_fraction}: the dyed core's share of the radius, in (0, 1]")
    if not (psf_sigma >= 0 and photons > 0 and background >= 0):
        raise InputError(
            f"psf_sigma = {psf_sigma}, photons = {photons}, background = {background}: need psf_sigma >= 0 "
            "[a], photons > 0 and background >= 0 [counts per pixel]"
        )
    # light from discs up to a core radius plus four PSF widths beyond the frame's edge reaches it
    margin = int(np.ceil((dyed_fraction * radii.max() + 4 * psf_sigma) / pixel_size)) + 1
    centres, which = _periodic_images(positions, lx, ly, le_offset)
    coverage = _disc_coverage(
        centres, dyed_fraction * radii[which], shape, pixel_size, margin, (-lx / 2, -ly / 2)
    )
    blurred = ndimage.gaussian_filter(coverage, psf_sigma / pixel_size, mode="constant")
    expected = photons * blurred[margin:-margin, margin:-margin] + background
    return rng.poisson(expected).astype(np.float64)


# ---- tracking ----------------------------------------------------------------------------------------
@dataclass
class TrackedFrame:
    """Particles located in a frame: ``positions`` (N', 2) [a] in the box [-Lx/2, Lx/2) x [-Ly/2, Ly/2),
    ``radii`` (N',) [a] (each the nominal radius of its species), ``box`` (Lx, Ly) [a] (the field of
    view), ``sizes`` (N',) [pixels] (trackpy's radius of gyration, what the species are read from),
    ``size_threshold`` [pixels] (between the two species' sizes) and ``precision`` [a] (trackpy's
    estimate of the static position error per coordinate, the median over the particles)."""

    positions: np.ndarray
    radii: np.ndarray
    box: tuple[float, float]
    sizes: np.ndarray
    size_threshold: float
    precision: float


def _import_trackpy():
    try:
        import trackpy
    except ImportError as exc:
        raise InputError(
            "track_frame needs trackpy, which is not installed: pip install rheograph[microscope]"
        ) from exc
    trackpy.quiet()  # its per-frame log lines
    return trackpy


def _periodic_padding(image: np.ndarray, pad: int, le_offset_px: float) -> np.ndarray:
    """``image`` with ``pad`` pixels of its periodic images around it: rows above the frame are its
    bottom rows shifted by +le_offset_px in x (interpolated: the offset is no whole number of pixels),
    those below its top rows shifted back, then columns wrapped."""
    above = ndimage.shift(image[:pad], (0, le_offset_px), order=3, mode="grid-wrap")
    below = ndimage.shift(image[-pad:], (0, -le_offset_px), order=3, mode="grid-wrap")
    tall = np.concatenate([below, image, above])
    return np.concatenate([tall[:, -pad:], tall, tall[:, :pad]], axis=1)


def min_image(delta: np.ndarray, lx: float, ly: float, le_offset: float) -> np.ndarray:
    """Separations (..., 2) [a] mapped to their nearest periodic image under Lees–Edwards."""
    out = np.array(delta, dtype=np.float64)
    images = np.round(out[..., 1] / ly)
    out[..., 1] -= images * ly
    out[..., 0] -= images * le_offset
    out[..., 0] -= lx * np.round(out[..., 0] / lx)
    return out


def _drop_images(positions, lx: float, ly: float, le_offset: float, closer_than: float) -> np.ndarray:
    """Indices of ``positions`` (M, 2) [a] to keep: of features within ``closer_than`` [a] of each other
    across the box's edges (one particle seen on both sides of a boundary) only the first."""
    near = (np.abs(positions[:, 0]) > lx / 2 - closer_than) | (np.abs(positions[:, 1]) > ly / 2 - closer_than)
    keep = list(np.flatnonzero(~near))
    kept_near = []
    for k in np.flatnonzero(near):
        gaps = min_image(positions[kept_near] - positions[k], lx, ly, le_offset)
        if not kept_near or np.hypot(gaps[:, 0], gaps[:, 1]).min() >= closer_than:
            kept_near.append(k)
    return np.sort(np.array(keep + kept_near, dtype=np.int64))


def two_means(values) -> float:
    """The threshold between the two groups of ``values`` (1-D 2-means, Lloyd's iteration from the
    extremes): the midpoint of the two groups' means."""
    values = np.asarray(values, dtype=np.float64).reshape(-1)
    threshold = 0.5 * (values.min() + values.max())
    for _ in range(100):
        low, high = values[values < threshold], values[values >= threshold]
        if not low.size or not high.size:
            break
        updated = 0.5 * (low.mean() + high.mean())
        if updated == threshold:
            break
        threshold = updated
    return float(threshold)


def two_species_threshold(sizes) -> float:
    """The size threshold between two species (``two_means``); refuses sizes that do not form two
    separate groups (means closer than four pooled standard deviations: more than ~2 % of the particles
    would be misassigned)."""
    sizes = np.asarray(sizes, dtype=np.float64)
    threshold = two_means(sizes) if sizes.size else math.nan
    low, high = sizes[sizes < threshold], sizes[sizes >= threshold]
    spread = math.sqrt((low.var() * low.size + high.var() * high.size) / sizes.size) if sizes.size > 3 else 0
    if low.size < 2 or high.size < 2 or high.mean() - low.mean() < 4 * spread:
        raise InputError(
            "radii: the tracked particles' sizes do not fall into two separate groups (small and large): "
            "check diameter_px (the largest particles' bright disc in pixels) and the focus"
        )
    return threshold


def locate_particles(
    image,
    pixel_size: float,
    diameter_px: int,
    le_offset: float = 0.0,
    separation_px: float | None = None,
    minmass: float | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Particles of a frame (rows, columns) whose field of view is the periodic box, located with
    ``trackpy.locate``: positions (M, 2) [a] in [-Lx/2, Lx/2) x [-Ly/2, Ly/2), trackpy's sizes (M,)
    [pixels] (radius of gyration of the brightness) and its static error estimates (M,) [a].

    ``pixel_size`` [a per pixel]; ``diameter_px``: trackpy's feature diameter, odd, at least the largest
    particles' bright disc (core plus PSF blur) in pixels; ``le_offset`` [a]: the Lees–Edwards offset
    (the frame is padded with its periodic images, so particles cut by an edge are found once, whole).
    ``separation_px``: features closer than this are one particle; default 1.5 a (no two centres are
    closer than 2 a, two small particles in contact).  ``minmass``: trackpy's least integrated
    brightness of a particle; by default none, and instead a feature is a particle where the frame
    (smoothed over a pixel) is brighter at its centre than ``two_means`` of its pixels, the midpoint of
    its dark and bright levels: a particle's core, not a shot-noise peak in a gap (a rule that holds in
    sparse and dense frames alike, where a fraction of the features' masses does not)."""
    trackpy = _import_trackpy()
    image = np.asarray(image, dtype=np.float64)
    if image.ndim != 2 or min(image.shape) < 3 or not np.all(np.isfinite(image)):
        raise InputError(f"image: must be a 2D array of finite pixel values, found shape {image.shape}")
    if not (math.isfinite(pixel_size) and pixel_size > 0):
        raise InputError(f"pixel_size = {pixel_size}: must be a positive length [a per pixel]")
    if int(diameter_px) != diameter_px or diameter_px < 3 or diameter_px % 2 == 0:
        raise InputError(f"diameter_px = {diameter_px}: trackpy's feature diameter, an odd integer >= 3")
    diameter_px = int(diameter_px)
    rows, cols = image.shape
    lx, ly = cols * pixel_size, rows * pixel_size
    separation_px = 1.5 / pixel_size if separation_px is None else separation_px
    pad = diameter_px + int(np.ceil(separation_px))
    padded = _periodic_padding(image, pad, le_offset / pixel_size)
    features = trackpy.locate(padded, diameter_px, separation=separation_px, minmass=minmass or 0)
    if minmass is None:
        smooth = ndimage.gaussian_filter(padded, 1.0)
        centre = smooth[features["y"].round().astype(int), features["x"].round().astype(int)]
        features = features[centre > two_means(smooth[pad:-pad, pad:-pad])]
    x_px, y_px = features["x"].to_numpy() - pad, features["y"].to_numpy() - pad
    # the primary frame spans pixel edges -1/2 .. cols - 1/2; its images beyond are the padding's
    inside = (x_px >= -0.5) & (x_px < cols - 0.5) & (y_px >= -0.5) & (y_px < rows - 0.5)
    xy = np.stack([-lx / 2 + (x_px + 0.5) * pixel_size, -ly / 2 + (y_px + 0.5) * pixel_size], axis=1)
    xy = wrap_into_box(xy[inside], lx, ly, le_offset)
    keep = _drop_images(xy, lx, ly, le_offset, separation_px * pixel_size)
    sizes = features["size"].to_numpy()[inside][keep]
    return xy[keep], sizes, features["ep"].to_numpy()[inside][keep] * pixel_size


def track_frame(
    image,
    pixel_size: float,
    diameter_px: int,
    le_offset: float = 0.0,
    radii: tuple[float, float] = (1.0, 1.4),
    separation_px: float | None = None,
    minmass: float | None = None,
) -> TrackedFrame:
    """The particles of a frame located (``locate_particles``, whose arguments these are) and sorted
    into two species by trackpy's ``size`` (radius of gyration: independent of brightness, so of
    bleaching and uneven illumination) split at ``two_species_threshold``; each is given its species'
    nominal radius of ``radii`` = (small, large) [a]."""
    positions, sizes, errors = locate_particles(
        image, pixel_size, diameter_px, le_offset, separation_px, minmass
    )
    threshold = two_species_threshold(sizes)
    return TrackedFrame(
        positions=positions,
        radii=np.where(sizes < threshold, float(min(radii)), float(max(radii))),
        box=(image.shape[1] * pixel_size, image.shape[0] * pixel_size),
        sizes=sizes,
        size_threshold=threshold,
        precision=float(np.nanmedian(errors)) if np.isfinite(errors).any() else math.nan,
    )


# ---- to a snapshot -----------------------------------------------------------------------------------
def check_particle_count(radii, box, phi: float, parameter: str = "phi") -> None:
    """Refuses tracked radii (N',) [a] whose area fraction in ``box`` [a] differs from the stated
    ``phi`` by more than ``PHI_TOLERANCE``: particles missed or merged by tracking (or spurious ones)
    change N and the area, and the surrogates read both; rescaling the box to hide it would compress
    the packing and put false overlaps in it."""
    measured = area_fraction(radii, *box)
    if not math.isclose(measured, phi, abs_tol=PHI_TOLERANCE):
        small = math.pi * min(radii) ** 2 / (box[0] * box[1])
        raise InputError(
            f"{parameter} = {phi:g} but the {len(radii)} tracked particles cover {measured:.4f} of the field "
            f"of view (a small particle is {small:.1e}): tracking missed, merged or invented about "
            f"{abs(phi - measured) / small:.0f} small particle(s); fix the tracking (diameter_px, minmass) "
            "rather than the area fraction"
        )


def snapshot_from_frame(
    tracked: TrackedFrame,
    le_offset: float,
    stress: float | None,
    phi: float,
    params: dict,
    position_noise: float,
    source: str = "microscope frame",
) -> Snapshots:
    """The one-snapshot ``Snapshots`` a surrogate reads (``Surrogate.predict_snapshots``) from a tracked
    frame: its box is the field of view, ``le_offset`` [a] the Lees–Edwards offset the user knows (the
    accumulated strain × Ly, modulo Lx), ``stress`` σ/σ0, ``phi`` the area fraction measured
    independently of the tracking (``check_particle_count`` compares the two), ``params`` the physical
    parameters (``PHYSICAL_PARAMS``, ``sim.*`` names: those of the model's card) and ``position_noise``
    [a] the tracking precision, RMS per coordinate (measured, e.g. on immobilised particles, or stated)."""
    check_particle_count(tracked.radii, tracked.box, phi)
    values = {
        "positions": tracked.positions,
        "radii": tracked.radii,
        "box": np.array(tracked.box),
        "le_offset": le_offset,
        "stress": stress,
        "phi": phi,
        "position_noise": position_noise,
        **params,
    }
    return snapshots_from_values(values, source, kind="api")


# ---- a table in micrometres --------------------------------------------------------------------------
def from_micrometres(
    table_xy_um, radii_um, box_um, small_radius_um: float, size_ratio: float = 1.4, origin: str = "corner"
) -> tuple[np.ndarray, np.ndarray, tuple[float, float]]:
    """Positions (N, 2) [a], radii (N,) [a] and box (Lx, Ly) [a] of an (x, y, r) table in µm: every
    length divided by the small particles' radius ``small_radius_um`` [µm] (a radius, not a diameter);
    each radius given the nominal radius of its species, 1 or ``size_ratio``, whichever is nearer in log
    (the models know two radii only); a radius more than ``SPECIES_SPREAD`` from both is refused.
    ``table_xy_um`` (N, 2) [µm] measured from the field of view's lower-left ``corner`` or its
    ``centre`` (``origin``); ``box_um`` (Lx, Ly) [µm], the field of view.  Positions are returned in the
    box [-Lx/2, Lx/2) x [-Ly/2, Ly/2)."""
    xy = np.asarray(table_xy_um, dtype=np.float64)
    radii = np.asarray(radii_um, dtype=np.float64).reshape(-1)
    box = np.asarray(box_um, dtype=np.float64).reshape(-1)
    if origin not in ("corner", "centre"):
        raise InputError(f"origin = {origin!r}: 'corner' (lower-left of the field of view) or 'centre'")
    if not (math.isfinite(small_radius_um) and small_radius_um > 0):
        raise InputError(f"small_radius_um = {small_radius_um}: must be a positive length [µm]")
    if box.size != 2 or not np.all(np.isfinite(box)) or box.min() <= 0:
        raise InputError(f"box_um: must be two positive lengths (Lx, Ly) [µm], found {box.tolist()}")
    if xy.ndim != 2 or xy.shape[1] != 2 or not np.all(np.isfinite(xy)):
        raise InputError(f"table_xy_um: must be (N, 2) finite positions [µm], found shape {xy.shape}")
    if radii.shape != (len(xy),) or not np.all(np.isfinite(radii)) or np.any(radii <= 0):
        bad = radii[~(radii > 0)]
        raise InputError(
            f"radii_um: must be ({len(xy)},) positive radii [µm], one per row of the table"
            + (f"; found {bad[0]:g}" if bad.size else "")
        )
    low = -box / 2 if origin == "centre" else np.zeros(2)
    outside = np.flatnonzero(np.any((xy < low) | (xy >= low + box), axis=1))
    if outside.size:
        k = outside[0]
        raise InputError(
            f"table_xy_um: {outside.size} point(s) outside the field of view {box.tolist()} µm from its "
            f"{origin} (row {k}: {xy[k].tolist()}): check box_um and origin"
        )
    ratio = radii / small_radius_um
    nearer_small = np.abs(np.log(ratio)) <= np.abs(np.log(ratio / size_ratio))
    species = np.where(nearer_small, 1.0, size_ratio)
    off = np.flatnonzero(np.abs(ratio / species - 1) > SPECIES_SPREAD)
    if off.size:
        k = off[0]
        raise InputError(
            f"radii_um: {off.size} radius/radii more than {SPECIES_SPREAD:.0%} from both species (row {k}: "
            f"{radii[k]:g} µm, species {small_radius_um:g} and {small_radius_um * size_ratio:g} µm): is "
            "small_radius_um the small particles' radius (not their diameter)?"
        )
    lx, ly = box / small_radius_um
    positions = (xy - low - box / 2) / small_radius_um
    return wrap_into_box(positions, lx, ly, 0.0), species, (float(lx), float(ly))
