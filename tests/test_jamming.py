"""The jam rule (rheograph.learn.jamming): a map of which trained state points jammed, read at the nearest
state point, scored per held-out trajectory."""

import numpy as np
import pytest

from rheograph.learn.jamming import fit_jam_map, jam_rule_scores, jammed_fraction


def snapshots(runs):
    """Per-snapshot arrays from (phi, sigma, jammed?) per run, three snapshots each; a jammed run has
    flowing snapshots and one arrested one (as the runner writes them)."""
    phi, stress, run_id, jammed = [], [], [], []
    for k, (p, s, jam) in enumerate(runs):
        phi += [p] * 3
        stress += [s] * 3
        run_id += [k] * 3
        jammed += [False, False, jam]
    return np.array(phi), np.array(stress), np.array(run_id), np.array(jammed)


TRAIN = [
    (0.80, 10.0, False),
    (0.80, 10.0, False),
    (0.80, 50.0, True),
    (0.80, 50.0, False),
    (0.80, 200.0, True),
    (0.80, 200.0, True),
    (0.76, 200.0, False),
]


def test_the_map_counts_trajectories_not_snapshots():
    jam_map = fit_jam_map(*snapshots(TRAIN))
    rows = list(zip(jam_map["phi"], jam_map["stress"], jam_map["runs"], jam_map["jammed_runs"]))
    assert rows == [(0.76, 200.0, 1, 0), (0.80, 10.0, 2, 0), (0.80, 50.0, 2, 1), (0.80, 200.0, 2, 2)]


def test_the_fraction_is_read_at_the_nearest_state_point():
    jam_map = fit_jam_map(*snapshots(TRAIN))
    got = jammed_fraction(
        jam_map, [0.80, 0.80, 0.79, 0.80, 0.77, 0.80], [50.0, 150.0, 300.0, 20.0, 200.0, 0.5]
    )
    # 150 is nearer 200 than 50 in log sigma; 0.79 reads phi = 0.80; 20 is nearer 10 (log 2) than 50
    # (log 2.5); 0.77 reads 0.76; sigma = 0.5 below the map takes its lowest stress
    np.testing.assert_allclose(got, [0.5, 1.0, 1.0, 0.0, 0.0, 0.0])


def test_the_rule_is_scored_per_held_out_trajectory():
    jam_map = fit_jam_map(*snapshots(TRAIN))
    held_out = [(0.80, 200.0, True), (0.80, 50.0, True), (0.80, 10.0, True), (0.80, 10.0, False)]
    scores = jam_rule_scores(jam_map, *snapshots(held_out))
    # 200: jammed, right; 50: share 0.5 -> jammed, right; 10: share 0 -> flowing, wrong then right
    assert scores == {"jam_accuracy": pytest.approx(0.75), "n_runs": 4, "n_jammed_runs": 3}
    assert np.isnan(jam_rule_scores(jam_map, [], [], [], [])["jam_accuracy"])
