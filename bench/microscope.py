"""What tracking a microscope frame costs the imaging surrogate, against Gaussian noise of the same RMS
error: the held-out test snapshots of the shipped ``N400_phi0.76_imaging`` model (each fold model on the
trajectories its training held out, as bench/snapshot_noise.py scores them; steady snapshots, strain >=
the model's min_strain, every ``--every``-th) rendered as fluorescence frames (rheograph.microscope:
dyed cores, Gaussian PSF, shot noise), located with trackpy and sorted into the two species, then
predicted (a) from the tracked positions and radii and (b) from the true positions plus Gaussian noise
whose RMS per coordinate equals that frame's measured tracking error, both told that error as
``position_noise``.  Tracking is scored against the truth (one-to-one matching within 0.5 a, periodic
minimum image): RMS error per coordinate, particles missed and spurious, species misassigned.  A frame
whose tracked particles do not give the stated φ (particles lost) is refused, as
``snapshot_from_frame`` refuses it, and counted.

    python -m bench.microscope                         # the defaults: every steady test snapshot, ~12 min
    python -m bench.microscope --every 1 --uniform-frames 20

``--uniform-frames K``: also K frames of uniformly dyed particles (dyed fraction 1), scored for tracking
only.  Writes docs/results/microscope/<name>.json and .md and the record of the tutorial's section
(docs/results/bench/microscope_bench.json) unless ``--no-write``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
import time
from pathlib import Path

import numpy as np
from scipy.optimize import linear_sum_assignment

ROOT = Path(__file__).resolve().parents[1]
from bench.publishing import Section, command_line, publish  # noqa: E402

METRICS = (("r2_log_eta", "R² log η_r"), ("r2_log_pressure", "R² log Π"), ("r2_z_mu", "R² Z_μ"))
MATCH_WITHIN = 0.5  # [a]: a tracked particle farther than this from every true one is spurious


def match(tracked, truth, box, le_offset: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One-to-one matching of tracked (M, 2) to true (N, 2) positions [a] by least total distance
    (periodic minimum image); (tracked index, true index, distance [a]) of the pairs within
    ``MATCH_WITHIN``."""
    from rheograph.microscope import min_image

    gaps = min_image(tracked[:, None] - truth[None], box[0], box[1], le_offset)
    distance = np.hypot(gaps[..., 0], gaps[..., 1])
    rows, cols = linear_sum_assignment(distance)
    close = distance[rows, cols] < MATCH_WITHIN
    return rows[close], cols[close], distance[rows, cols][close]


def tracking_record(tracked, snaps, k: int) -> dict:
    """How a tracked frame of snapshot ``k`` compares with its truth."""
    truth = snaps.positions[k]
    mine, theirs, distance = match(tracked.positions, truth, (snaps.lx, snaps.ly), snaps.le_offset[k])
    return {
        "n_true": int(len(truth)),
        "n_tracked": int(len(tracked.positions)),
        "missed": int(len(truth) - len(theirs)),
        "spurious": int(len(tracked.positions) - len(mine)),
        "misassigned": int(np.sum(tracked.radii[mine] != snaps.radii[theirs])),
        "rms_error": float(np.sqrt(np.mean(distance**2) / 2)) if len(distance) else math.nan,
        "trackpy_precision": tracked.precision,
    }


def one_snapshot(snaps, k: int) -> object:
    return dataclasses.replace(snaps.select(slice(k, k + 1)), contacts=None)


def _bitwise_equal(a, b) -> bool:
    """Equal tensors, NaN where the other has NaN (unused features' scaling is NaN)."""
    import torch

    return (
        a.shape == b.shape
        and a.dtype == b.dtype
        and bool(torch.equal(a.view(-1).view(torch.uint8), b.view(-1).view(torch.uint8)))
    )


def same_model(a: Path, b: Path) -> bool:
    """Whether two bundles hold the same network and graph settings (the weights bit for bit; their file
    format may differ: read_bundle upgrades older ones)."""

    from rheograph.learn.bundle import read_bundle

    first, second = read_bundle(a), read_bundle(b)
    return (
        first["state_dict"].keys() == second["state_dict"].keys()
        and all(_bitwise_equal(v, second["state_dict"][k]) for k, v in first["state_dict"].items())
        and first["graph"] == second["graph"]
        and first["fold"] == second["fold"]
    )


def fold_frames(model_dir: Path, run_dir: Path, fold: int, args, log) -> list[dict]:
    """Records of every scored frame of fold ``fold``'s held-out trajectories."""
    import rheograph
    from rheograph.errors import InputError
    from rheograph.io.configurations import noisy_positions
    from rheograph.microscope import render_frame, snapshot_from_frame, track_frame

    bundle = model_dir / f"fold{fold}.pt"
    trained = run_dir / f"fold{fold}.pt"
    assert same_model(bundle, trained), (
        f"{bundle} is not the model trained in {run_dir}: its test split is unknown"
    )
    model = rheograph.load_model(bundle)
    split = json.loads((run_dir / f"fold{fold}_split.json").read_text())
    held_out = np.unique(np.load(run_dir / f"fold{fold}_predictions.npz")["run_id"])
    records = []
    for run in held_out:
        name = split["files"][int(run)]
        path = ROOT / name[name.index("data/") :]
        snaps = rheograph.read_snapshots(path)
        steady = np.flatnonzero(snaps.strain >= model.min_strain)[:: args.every]
        for k in steady:
            rng = np.random.default_rng([args.seed, fold, int(run), int(k)])
            pixel = snaps.lx / round(snaps.lx / args.pixel_size)  # the box a whole number of pixels
            frame = render_frame(
                snaps.positions[k], snaps.radii, (snaps.lx, snaps.ly), pixel, args.psf, args.photons,
                args.background, rng, le_offset=snaps.le_offset[k], dyed_fraction=args.dyed_fraction,
            )  # fmt: skip
            tracked = track_frame(frame, pixel, args.diameter_px, le_offset=snaps.le_offset[k])
            record = {"fold": fold, "source": str(path.relative_to(ROOT)), "snapshot": int(k)}
            record.update(tracking_record(tracked, snaps, k))
            record["stress"] = snaps.stress
            record["truth"] = snaps.targets[k].tolist()
            record["jammed"] = bool(snaps.jammed[k])
            eps = record["rms_error"]
            try:
                frame_snaps = snapshot_from_frame(
                    tracked, snaps.le_offset[k], snaps.stress, snaps.phi, snaps.params, eps, source=str(path)
                )
            except InputError as exc:
                record["refused"] = str(exc)
                records.append(record)
                continue
            frame_snaps.strain[:] = snaps.strain[k]
            frame_snaps.targets[:] = snaps.targets[k]
            gauss = dataclasses.replace(
                one_snapshot(snaps, k),
                positions=noisy_positions(snaps, k, eps, rng)[None],
                position_noise=eps,
            )
            for label, source in (("tracked", frame_snaps), ("gaussian", gauss)):
                table = model.predict_snapshots(source)
                record[label] = {
                    "pred": [float(table[f"{t}_pred"][0]) for t in ("eta", "pressure", "z_mu")],
                    "in_domain": int(table["in_domain"][0]),
                    "notes": str(table["notes"][0]),
                }
            records.append(record)
        log(f"fold {fold}: {path.parent.name} done ({len(records)} frames)")
    return records


def uniform_frames(run_dir: Path, count: int, args) -> list[dict]:
    """Tracking records of ``count`` frames of uniformly dyed particles (fold 0's held-out
    trajectories, their first steady snapshots in turn): positions located, then whether the sizes
    split into two species."""
    import rheograph
    from rheograph.errors import InputError
    from rheograph.microscope import TrackedFrame, locate_particles, render_frame, two_species_threshold

    split = json.loads((run_dir / "fold0_split.json").read_text())
    held_out = np.unique(np.load(run_dir / "fold0_predictions.npz")["run_id"])
    records = []
    for n in range(count):
        name = split["files"][int(held_out[n % len(held_out)])]
        path = ROOT / name[name.index("data/") :]
        snaps = rheograph.read_snapshots(path)
        k = int(np.flatnonzero(snaps.strain >= 1.0)[n // len(held_out)])
        rng = np.random.default_rng([args.seed, 99, n])
        pixel = snaps.lx / round(snaps.lx / args.pixel_size)
        frame = render_frame(
            snaps.positions[k], snaps.radii, (snaps.lx, snaps.ly), pixel, args.psf, args.photons,
            args.background, rng, le_offset=snaps.le_offset[k], dyed_fraction=1.0,
        )  # fmt: skip
        diameter = odd_diameter(1.0, args.psf, pixel)
        positions, sizes, errors = locate_particles(frame, pixel, diameter, le_offset=snaps.le_offset[k])
        record = {"source": str(path.relative_to(ROOT)), "snapshot": k, "diameter_px": diameter}
        try:
            threshold = two_species_threshold(sizes)
            radii = np.where(sizes < threshold, 1.0, 1.4)
        except InputError as exc:
            record["refused"] = str(exc)
            threshold, radii = math.nan, np.full(len(sizes), math.nan)  # no species: all misassigned
        tracked = TrackedFrame(
            positions, radii, (snaps.lx, snaps.ly), sizes, threshold, float(np.median(errors))
        )
        record.update(tracking_record(tracked, snaps, k))
        records.append(record)
    return records


def odd_diameter(dyed_fraction: float, psf: float, pixel: float, large: float = 1.4) -> int:
    """trackpy's feature diameter [pixels]: the large particles' dyed core plus one PSF width each side,
    rounded up to an odd number."""
    size = math.ceil(2 * (dyed_fraction * large + psf) / pixel)
    return size + 1 - size % 2


def score(records: list[dict], label: str) -> dict:
    from rheograph.learn.module import fold_metrics

    used = [r for r in records if "refused" not in r]
    pred = np.array([r[label]["pred"] for r in used])
    true = np.array([r["truth"] for r in used])
    groups = np.array([r["stress"] for r in used])  # one state point per stress at this phi
    out = fold_metrics(pred, true, groups, np.array([r["jammed"] for r in used]))
    out["in_domain"] = float(np.mean([r[label]["in_domain"] for r in used]))
    return out


def summary(records: list[dict], uniform: list[dict]) -> dict:
    used = [r for r in records if "refused" not in r]
    errors = [r["rms_error"] for r in records]
    counts = ("missed", "spurious", "misassigned")
    tracking = {
        "frames": len(records),
        "refused": len(records) - len(used),
        "rms_error_mean": float(np.mean(errors)),
        "rms_error_range": [float(min(errors)), float(max(errors))],
        "trackpy_precision_mean": float(np.nanmean([r["trackpy_precision"] for r in records])),
        **{key: int(sum(r[key] for r in records)) for key in counts},
        "particles": int(sum(r["n_true"] for r in records)),
    }
    out = {"tracking": tracking, "tracked": score(records, "tracked"), "gaussian": score(records, "gaussian")}
    if uniform:
        out["uniform_dyed"] = {
            "frames": len(uniform),
            "species_refused": sum("refused" in r for r in uniform),
            "rms_error_mean": float(np.mean([r["rms_error"] for r in uniform])),
            **{key: int(sum(r[key] for r in uniform)) for key in ("missed", "spurious")},
            "particles": int(sum(r["n_true"] for r in uniform)),
        }
    return out


def markdown(result: dict, command: str) -> str:
    s, t = result["summary"], result["summary"]["tracking"]
    c = result["config"]
    every = "every" if c["every"] == 1 else f"every {c['every']}-th"
    lines = [
        f"# Tracked frames against Gaussian noise: {c['model']}",
        "",
        f"{t['frames']} held-out test frames ({every} steady snapshot of the test "
        f"trajectories, each fold model on its own), pixel {c['pixel_size']:g} a, PSF σ {c['psf']:g} a, "
        f"{c['photons']:g} photons per pixel on a dyed core of {c['dyed_fraction']:g} of the radius, "
        f"background {c['background']:g}, trackpy diameter {c['diameter_px']} px.",
        "",
        f"Tracking: RMS error {t['rms_error_mean']:.4f} a per coordinate (frames "
        f"{t['rms_error_range'][0]:.4f}–{t['rms_error_range'][1]:.4f}; trackpy's own estimate "
        f"{t['trackpy_precision_mean']:.4f}); of {t['particles']} particles {t['missed']} missed, "
        f"{t['spurious']} spurious, {t['misassigned']} of the wrong species; {t['refused']} frame(s) "
        "refused (tracked φ off the stated one).",
        "",
        "| positions | " + " | ".join(label for _, label in METRICS) + " | fluct. η_r | in domain |",
        "|---|" + "---|" * (len(METRICS) + 2),
    ]
    for key, label in (("tracked", "tracked frames"), ("gaussian", "true + Gaussian noise of the same RMS")):
        row = s[key]
        cells = " | ".join(f"{row[m]:.4f}" for m, _ in METRICS)
        lines.append(f"| {label} | {cells} | {row['fluct_eta']:.3f} | {row['in_domain']:.0%} |")
    gap = s["tracked"]["r2_log_eta"] - s["gaussian"]["r2_log_eta"]
    lines += ["", f"Tracked − Gaussian, R² log η_r: {gap:+.4f} (goal: within 0.02)."]
    if "uniform_dyed" in s:
        u = s["uniform_dyed"]
        lines += [
            "",
            f"Uniformly dyed particles (dyed fraction 1), {u['frames']} frames, tracking only: RMS error "
            f"{u['rms_error_mean']:.3f} a per coordinate, {u['missed']} of {u['particles']} particles "
            f"missed, {u['spurious']} spurious; sizes not separable into two species in "
            f"{u['species_refused']} of {u['frames']} frames.",
        ]
    lines += ["", f"Command: `{command}`", ""]
    return "\n".join(lines)


def count(n: int) -> str:
    """A count as the tutorial prints it: ``none`` for 0, thousands grouped by a space."""
    return "none" if n == 0 else f"{n:,}".replace(",", " ")


def fraction_words(fraction: float) -> str:
    """The dyed core's share of the radius in words where it has a common one."""
    return {0.5: "half the radius"}.get(fraction, f"{fraction:g} of the radius")


def section(result: dict, command: str) -> Section:
    """The tutorial's section from a run's result (``result``: config, summary, frames, seconds): the frames
    and optics, the tracking error, the table of tracked against Gaussian positions, what uniformly dyed
    particles give, and the command."""
    c, s = result["config"], result["summary"]
    t, u = s["tracking"], s.get("uniform_dyed")
    trajectories = len({r["source"] for r in result["frames"]})
    every = "every steady snapshot" if c["every"] == 1 else f"every {c['every']}-th steady snapshot"
    out = Section(
        f"{t['frames']} frames: {every} (strain ≥ 1) of the {trajectories} trajectories, each scored once, "
        "by the fold",
        f"model that did not see it.  Settings: {c['pixel_size']:g} a pixels, PSF σ {c['psf']:g} a, dyed "
        f"cores of {fraction_words(c['dyed_fraction'])},",
        f"{c['photons']:g} photons per pixel on a core and a background of {c['background']:g}.  The "
        f"tracking error was {t['rms_error_mean']:.4f} a RMS per",
        f"coordinate (frames {t['rms_error_range'][0]:.4f}–{t['rms_error_range'][1]:.4f} a; trackpy's own "
        f"estimate {t['trackpy_precision_mean']:.4f} a).  Of {count(t['particles'])} particles "
        f"{count(t['missed'])} were",
        f"missed, {count(t['spurious'])} spurious and {count(t['misassigned'])} of the wrong species.",
        "",
    )
    rows = [
        [label]
        + [f"{s[key][m]:.4f}" for m, _ in METRICS]
        + [f"{s[key]['fluct_eta']:.3f}", f"{s[key]['in_domain']:.0%}"]
        for key, label in (
            ("tracked", "tracked frames"),
            ("gaussian", "true + Gaussian noise of the same RMS"),
        )
    ]
    out.table(["positions"] + [label for _, label in METRICS] + ["fluct. η_r", "in domain"], rows)
    gap = s["tracked"]["r2_log_eta"] - s["gaussian"]["r2_log_eta"]
    signed_gap = f"{gap:+.4f}".replace("-", "−")  # the typographic minus of the page
    z_cost = s["gaussian"]["r2_z_mu"] - s["tracked"]["r2_z_mu"]
    out.add(
        "",
        "The goal was tracked within 0.02 of Gaussian in R² log η_r; the difference is "
        f"{signed_gap}.  At this",
        "precision the tracker's errors (pixel locking, bias from neighbours' light) cost nothing beyond "
        "their",
        f"RMS in η_r and Π; in Z_μ they cost {z_cost:.3f} of R².  Uniformly dyed particles, on "
        f"{u['frames']} frames with the same",
        f"optics and `diameter_px` {odd_diameter(1.0, c['psf'], c['pixel_size'])} (the whole large particle "
        "plus one PSF σ each side), gave an RMS error of",
        f"{u['rms_error_mean']:.2f} a: {u['missed']} of {u['particles']} particles missed, {u['spurious']} "
        "spurious, and sizes that split into two species in "
        + ("none of" if u["species_refused"] == u["frames"] else f"{u['frames'] - u['species_refused']} of"),
        f"the frames.  Details per frame: `docs/results/microscope/{c['name']}.json`.  About "
        f"{result['seconds'] / 60:.0f}",
        "minutes on one core:",
        "",
        "```bash",
        command,
        "```",
    )
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--model", default="N400_phi0.76_imaging")
    ap.add_argument(
        "--run-dir",
        default="docs/results/imaging/N400_phi0.76_relaxed_measured",
        help="the training run the shipped model was made from (its folds' test splits)",
    )
    ap.add_argument("--folds", type=int, nargs="+", default=[0, 1, 2, 3, 4])
    ap.add_argument("--every", type=int, default=1, help="every n-th steady snapshot of a test trajectory")
    ap.add_argument("--pixel-size", type=float, default=0.15, help="[a per pixel], rounded to fit the box")
    ap.add_argument("--psf", type=float, default=0.2, help="PSF standard deviation [a]")
    ap.add_argument("--photons", type=float, default=100.0, help="mean counts per pixel of a dyed core")
    ap.add_argument("--background", type=float, default=10.0, help="mean counts per pixel elsewhere")
    ap.add_argument("--dyed-fraction", type=float, default=0.5, help="dyed core radius / particle radius")
    ap.add_argument("--diameter-px", type=int, default=None, help="trackpy diameter (default: odd_diameter)")
    ap.add_argument("--uniform-frames", type=int, default=6, help="uniformly dyed frames, tracking only")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--name", default="N400_phi0.76_imaging")
    ap.add_argument("--no-write", action="store_true")
    args = ap.parse_args(argv)
    from rheograph.learn.registry import model_paths

    if args.diameter_px is None:
        args.diameter_px = odd_diameter(args.dyed_fraction, args.psf, args.pixel_size)
    model_dir = model_paths(args.model)[0][0].parent
    run_dir = ROOT / args.run_dir
    start = time.time()

    def log(text):
        print(f"[{time.time() - start:6.0f} s] {text}", file=sys.stderr, flush=True)

    records = [r for fold in args.folds for r in fold_frames(model_dir, run_dir, fold, args, log)]
    uniform = uniform_frames(run_dir, args.uniform_frames, args) if args.uniform_frames else []
    config = {key: getattr(args, key) for key in vars(args) if key != "no_write"}
    result = {"config": config, "summary": summary(records, uniform), "frames": records, "uniform": uniform}
    result["seconds"] = round(time.time() - start, 1)
    command = command_line("microscope.py", argv)
    result["command"] = command
    text = markdown(result, command)
    print(text)
    if not args.no_write:
        out = ROOT / "docs" / "results" / "microscope"
        out.mkdir(parents=True, exist_ok=True)
        (out / f"{args.name}.json").write_text(json.dumps(result, indent=1) + "\n")
        (out / f"{args.name}.md").write_text(text)
    # the tutorial's section: its record, which bench.render draws into the page
    publish("microscope_bench", section(result, command), not args.no_write, command=command)
    return 0


if __name__ == "__main__":
    sys.exit(main())
