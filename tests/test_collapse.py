"""The 2D/3D comparison against the distance to frictional jamming: each set's phi_J^mu recovered from
its own runs, a set that is the other one shifted in phi collapses exactly, an amplitude or a contact
number that differs is measured, and bad input is refused in one line."""

import json

import numpy as np
import pytest

from rheograph.analysis.collapse import interpolate, main
from rheograph.errors import InputError

STRESSES = (2.0, 200.0)


def _eta(phi, phi_j, amplitude):
    return amplitude * (phi_j - phi) ** -2.0


def _index(path, dim, n, phis, phi_j, amplitude=1.0, z_mu=2.0, pressure_ratio=1.5):
    """An index of exact power-law runs: eta_r = A (phi_J - phi)^-2 at every stress (the plateau is the
    largest), Pi/sigma and Z_mu constant, two seeds per state point."""
    runs = []
    for phi in phis:
        for stress in STRESSES:
            for seed in (1, 2):
                params = {"n_particles": n, "phi": phi, "stress": stress, "seed": seed, "mu": 0.5}
                if dim == 3:
                    params["dim"] = 3
                summary = {
                    "viscosity": _eta(phi, phi_j, amplitude) * (1.0 if stress == 200.0 else 0.5),
                    "pressure": pressure_ratio * stress,
                    "z_mu": z_mu,
                    "z": 2.0 * z_mu,
                }
                runs.append({"params": params, "status": "completed", "strain": 3.0, "summary": summary})
    path.write_text(json.dumps({"format": 1, "runs": runs}))
    return str(path)


def _run(tmp_path, three_amplitude=1.0, three_z_mu=2.0, argv=()):
    two = _index(tmp_path / "two.json", 2, 400, [0.74, 0.76, 0.77, 0.78, 0.785], 0.80)
    three = _index(tmp_path / "three.json", 3, 500, [0.54, 0.555, 0.565], 0.58, three_amplitude, three_z_mu)
    page = tmp_path / "page.md"
    page.write_text("<!-- collapse_2d_3d:start -->\n<!-- collapse_2d_3d:end -->\n")
    record = tmp_path / "record.json"
    main(
        [
            "--two",
            two,
            "--three",
            three,
            "--out",
            str(page),
            "--record",
            str(record),
            "--bootstrap",
            "20",
            *argv,
        ]
    )
    return json.loads(record.read_text())["figure"], page.read_text()


def test_a_set_shifted_in_phi_collapses_exactly_and_each_phi_j_mu_is_its_own(tmp_path):
    data, page = _run(tmp_path)
    assert data["two"]["phi_j_mu"] == pytest.approx(0.80, abs=1e-6)
    assert data["three"]["phi_j_mu"] == pytest.approx(0.58, abs=1e-6)
    # every 3D state point (distance 0.015-0.04) lies inside the 2D range (0.015-0.06) at both stresses
    assert len(data["matched"]) == 6
    for m in data["matched"]:
        assert m["eta_ratio"] == pytest.approx(1.0, rel=1e-6)
        assert m["pressure_ratio"] == pytest.approx(1.0, rel=1e-9)
        assert m["z_mu_difference"] == pytest.approx(0.0, abs=1e-12)
    assert "η_r 3D / 2D | 1 | 1–1" in page


def test_a_different_amplitude_and_contact_number_are_measured_not_collapsed(tmp_path):
    data, _ = _run(tmp_path, three_amplitude=3.0, three_z_mu=3.5)
    assert {round(m["eta_ratio"], 6) for m in data["matched"]} == {3.0}
    assert {round(m["z_mu_difference"], 9) for m in data["matched"]} == {1.5}
    # 3.5 of the spheres' 4 against 2 of the discs' 3: (3.5 / 4) / (2 / 3)
    assert {round(m["z_mu_isostatic_ratio"], 9) for m in data["matched"]} == {round(3.5 * 3 / 8, 9)}


def test_interpolation_is_exact_for_a_power_law_and_refuses_to_extrapolate():
    curve = [{"distance": d, "eta": d**-2.0, "z_mu": 1.0 + np.log(d)} for d in (0.01, 0.02, 0.08)]
    assert interpolate(curve, 0.04, "eta") == pytest.approx(0.04**-2.0, rel=1e-12)
    assert interpolate(curve, 0.04, "z_mu") == pytest.approx(1.0 + np.log(0.04), rel=1e-12)
    assert np.isnan(interpolate(curve, 0.1, "eta"))
    assert np.isnan(interpolate(curve[:1], 0.01, "eta"))


def test_bad_input_is_refused_in_one_line(tmp_path):
    two = _index(tmp_path / "two.json", 2, 400, [0.74, 0.76, 0.78], 0.80)
    with pytest.raises(InputError, match="another dimension than 3"):
        main(["--two", two, "--three", two])
    three = _index(tmp_path / "three.json", 3, 500, [0.54, 0.555, 0.565], 0.58)
    with pytest.raises(InputError, match="--method 'no such fit'"):
        main(["--two", two, "--three", three, "--method", "no such fit", "--bootstrap", "20"])
    with pytest.raises(InputError, match="no run with dim 3 and N = 2000"):
        main(["--two", two, "--three", three, "--n-three", "2000", "--bootstrap", "20"])
    with pytest.raises(InputError, match="--bootstrap 3"):
        main(["--two", two, "--three", three, "--bootstrap", "3"])
    with pytest.raises(InputError, match="--record: give the page too"):
        main(["--two", two, "--three", three, "--record", str(tmp_path / "r.json")])


def test_a_set_of_one_seed_per_state_point_gets_its_interval_from_the_block_errors(tmp_path):
    """``--single-run-error``: with one trajectory per state point and a 5 % block error on η_r, the
    φ_J^μ interval is empty when trajectories alone are resampled and a few 1e-3 wide otherwise,
    around the exact 0.58."""
    from rheograph.analysis.collapse import DEFAULT_METHOD, frictional_jamming_point
    from rheograph.analysis.jamming_points import read_runs

    path = tmp_path / "three.json"
    _index(path, 3, 500, [0.54, 0.555, 0.565], 0.58)
    index = json.loads(path.read_text())
    index["runs"] = [r for r in index["runs"] if r["params"]["seed"] == 1]
    for r in index["runs"]:
        r["summary"]["viscosity_se"] = 0.05 * r["summary"]["viscosity"]
    path.write_text(json.dumps(index))
    runs = read_runs([path])
    fixed = frictional_jamming_point(runs, 3, 500, DEFAULT_METHOD, 50)
    drawn = frictional_jamming_point(runs, 3, 500, DEFAULT_METHOD, 50, single_run_error=True)
    assert fixed["phi_j_ci"][0] == fixed["phi_j_ci"][1] == pytest.approx(0.58)
    low, high = drawn["phi_j_ci"]
    assert low < 0.58 < high and 5e-4 < high - low < 1e-2
