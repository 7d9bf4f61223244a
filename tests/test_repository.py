"""What a clone carries: the tracked files stay within the size a researcher downloads without thinking
twice (the 3D data, still growing, within a budget of their own), the shipped models stay
small, and run directories under docs/results keep reports, metrics and predictions, never weights,
event files or databases (the published numbers are re-read from those)."""

import json
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
CHECKOUT_LIMIT_BYTES = 310_000_000  # the 2D training data, models and results included
# the 3D data (every data/*_3d folder: the flow-curve set towards seven volume fractions, eight stresses and
# two to three seeds, its polydisperse, jamming, near-jamming and N = 2000 campaigns, and LF_DEM's 3D
# reference files) grow campaign by campaign: counted apart, within a budget of their own (a finished
# N = 500 run is 0.6-0.9 MB compacted)
DATA_3D_GLOB = "data/*_3d"
DATA_3D_LIMIT_BYTES = 115_000_000
SHIPPED_MODELS_LIMIT_BYTES = 15_000_000
# the shipped 3D models (per volume fraction, pooled, imaging; each card's domain says dim 3) grow with
# the 3D set: counted apart, within a budget of their own
SHIPPED_3D_MODELS_LIMIT_BYTES = 5_000_000
NOT_IN_RESULTS = (".pt", ".ckpt", ".db", ".sqlite", ".pkl", ".pickle")


def tracked_files() -> list[Path]:
    try:
        listed = subprocess.run(
            ["git", "-C", str(ROOT), "ls-files", "-z"], capture_output=True, check=True
        ).stdout
    except (OSError, subprocess.CalledProcessError):
        pytest.skip("not a git checkout")
    return [ROOT / name for name in listed.decode().split("\0") if name]


def test_the_checkout_stays_within_its_size():
    data_3d = set(ROOT.glob(DATA_3D_GLOB))
    sizes = {f: f.stat().st_size for f in tracked_files() if f.is_file()}
    in_data_3d = sum(size for f, size in sizes.items() if data_3d & set(f.parents))
    rest = sum(sizes.values()) - in_data_3d
    assert rest <= CHECKOUT_LIMIT_BYTES, f"tracked files outside {DATA_3D_GLOB}: {rest / 1e6:.1f} MB"
    assert in_data_3d <= DATA_3D_LIMIT_BYTES, f"{DATA_3D_GLOB}: {in_data_3d / 1e6:.1f} MB"


def test_the_shipped_models_stay_small():
    models = ROOT / "src" / "rheograph" / "models"
    totals = {2: 0, 3: 0}
    for f in tracked_files():
        if models in f.parents and f.is_file():
            card = json.loads((models / f.relative_to(models).parts[0] / "card.json").read_text())
            totals[card["domain"].get("dim", 2)] += f.stat().st_size
    assert 0 < totals[2] <= SHIPPED_MODELS_LIMIT_BYTES, f"shipped 2D models {totals[2] / 1e6:.1f} MB"
    assert 0 < totals[3] <= SHIPPED_3D_MODELS_LIMIT_BYTES, f"shipped 3D models {totals[3] / 1e6:.1f} MB"


def test_results_hold_no_weights_event_files_or_databases():
    results = ROOT / "docs" / "results"
    heavy = [
        f.relative_to(ROOT).as_posix()
        for f in tracked_files()
        if results in f.parents and (f.suffix in NOT_IN_RESULTS or f.name.startswith("events.out.tfevents"))
    ]
    assert heavy == []
