"""bench/train_speed.py's bookkeeping: the Pareto front of its figure against brute force, and time to
accuracy."""

import itertools

import numpy as np
import pytest
from conftest import load_bench_script

from bench.figures import pareto_front


@pytest.fixture(scope="module")
def train_speed():
    return load_bench_script("train_speed")


def test_pareto_front_matches_brute_force():
    rng = np.random.default_rng(3)
    points = [(float(c), float(s)) for c, s in zip(rng.integers(1, 6, 40), rng.integers(0, 6, 40))]
    front = set(pareto_front(points))
    for i, (c, s) in enumerate(points):
        dominated = any(
            c2 <= c and s2 >= s and (c2 < c or s2 > s) for j, (c2, s2) in enumerate(points) if j != i
        )
        assert (i in front) == (not dominated), (i, points[i])
    # along the front, a higher score always costs more
    ordered = sorted((points[i] for i in front), key=lambda p: p[0])
    for (c1, s1), (c2, s2) in itertools.pairwise(ordered):
        assert c2 > c1 or s2 == s1
        assert s2 >= s1


def test_time_to_accuracy_is_the_first_crossing(train_speed):
    curve = [{"seconds": 10.0 * k, "r2": r} for k, r in enumerate([0.1, 0.5, 0.92, 0.88, 0.97, 0.99])]
    assert train_speed.time_to(curve, "r2", 0.9) == 20.0  # first reached at epoch 2, not the later 0.97
    assert train_speed.time_to(curve, "r2", 0.99) == 50.0
    assert np.isnan(train_speed.time_to(curve, "r2", 0.999))  # never reached: NaN, not the last time
