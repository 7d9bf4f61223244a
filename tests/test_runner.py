"""Trajectory files, resume after interruption, jam detection, stability, bad input."""

import json
from pathlib import Path

import h5py
import numpy as np
import pytest

from rheograph.io.hdf5 import (
    TrajectoryFileError,
    is_compact,
    read_run_info,
    read_timeseries,
    respace_snapshots,
)
from rheograph.runs.runner import run_state_point
from rheograph.sim.params import ParameterError, SimParams

TINY = dict(
    n_particles=64,
    phi=0.74,
    stress=5.0,
    strain=0.12,
    output_interval=0.01,
    snapshot_interval=0.03,
    steady_state_strain=0.02,
    disp_max=2e-3,
)


def test_file_layout_and_snapshot_targets(tmp_path):
    path = tmp_path / "run.h5"
    out = run_state_point(SimParams(**TINY), path, progress=False)
    assert out.status == "completed"
    with h5py.File(path) as h5:
        assert h5.attrs["schema_version"] == 1 and h5.attrs["status"] == "completed"
        ts = h5["timeseries"]
        n = ts["time"].shape[0]
        assert n == 12 and ts["stress"].shape == (n, 3)
        np.testing.assert_allclose(ts["stress"][:, 1], 5.0, rtol=1e-9)  # stress control
        total = ts["stress_lubrication"][()] + ts["stress_contact"][()] + ts["stress_solvent"][()]
        np.testing.assert_allclose(total, ts["stress"][()], rtol=1e-12)
        np.testing.assert_allclose(ts["viscosity"][()], 5.0 / ts["shear_rate"][()], rtol=1e-9)
        sn = h5["snapshots"]
        assert sn["positions"].shape == (4, 64, 2)
        np.testing.assert_allclose(sn["strain"][()], [0.0, 0.03, 0.06, 0.09], atol=3e-3)
        off = sn["contact_offset"][()]
        assert off.shape == (5,) and off[-1] == sn["contact_pairs"].shape[0]
        # the snapshot targets are the instantaneous values of the rows at the same strain
        matched = 0
        for k, s in enumerate(sn["strain"][()]):
            row = np.argmin(np.abs(ts["strain"][()] - s))
            if abs(ts["strain"][row] - s) < 1e-12:
                assert sn["viscosity"][k] == pytest.approx(ts["viscosity"][row])
                matched += 1
        assert matched >= 1
        # Z_mu counts the frictional contacts of the stored contact list
        for k in range(4):
            states = sn["contact_state"][off[k] : off[k + 1]]
            assert sn["z_mu"][k] == pytest.approx(2 * np.sum(states >= 2) / 64)
    info = read_run_info(path)
    assert np.isfinite(info["summary"]["viscosity"])
    # the cost record of the scaling tables
    assert info["summary"]["steps"] > 0 and 50 < info["summary"]["peak_memory_mb"] < 24e3


def test_damage_found_after_the_file_opens_falls_back_to_the_last_checkpoint_copy(
    tmp_path, monkeypatch, caplog
):
    """A file whose superblock opens but whose checkpoint cannot be read (emulated: the first read of it
    raises KeyError, as HDF5 does for a bad object header) counts as damaged: the resume sets it aside,
    continues from the last-checkpoint copy, and ends at the uninterrupted run; without a copy the same
    damage is refused by name, the file closed (not left locked)."""
    import os
    import shutil

    import rheograph.io.hdf5 as hdf5

    params = SimParams(**TINY)
    ref = tmp_path / "ref.h5"
    run_state_point(params, ref, progress=False)
    cut = tmp_path / "cut.h5"
    run_state_point(params, cut, progress=False, max_steps=37)
    read_checkpoint = hdf5._state_from_checkpoint
    damaged_file = os.stat(cut).st_ino  # the restored file is another one (a copy moved into place)

    def read_unless_damaged(group):
        if os.stat(group.file.filename).st_ino == damaged_file:
            raise KeyError("Unable to synchronously open object (bad object header version number)")
        return read_checkpoint(group)

    monkeypatch.setattr(hdf5, "_state_from_checkpoint", read_unless_damaged)
    with pytest.raises(hdf5.DamagedTrajectoryError, match="cannot be read back"):
        run_state_point(params, cut, progress=False)  # no copy (closed cleanly): refused by name
    with h5py.File(cut, "r+"):  # and not left open by the failed attempt
        pass
    shutil.copyfile(cut, hdf5.last_checkpoint_copy(cut))  # what an unclean stop leaves beside it
    with caplog.at_level("WARNING", logger="rheograph"):
        assert run_state_point(params, cut, progress=False).status == "completed"
    assert "resuming from its copy as of the last checkpoint" in caplog.text
    assert (tmp_path / "cut.h5.damaged").exists() and not hdf5.last_checkpoint_copy(cut).exists()
    a, b = read_timeseries(ref), read_timeseries(cut)
    for key in a:
        np.testing.assert_array_equal(a[key], b[key], err_msg=key)


@pytest.mark.parametrize("lagged", [False, True])
def test_resume_reproduces_the_uninterrupted_trajectory(tmp_path, lagged):
    params = SimParams(**TINY, lagged_step_control=lagged)
    ref = tmp_path / "ref.h5"
    run_state_point(params, ref, progress=False)
    # interrupt twice at arbitrary points (between checkpoints: checkpoint interval forced tiny/huge)
    cut = tmp_path / "cut.h5"
    first = run_state_point(params, cut, progress=False, max_steps=37)
    assert first.status == "interrupted"
    second = run_state_point(params, cut, progress=False, max_steps=53)
    assert second.status == "interrupted"
    third = run_state_point(params, cut, progress=False)
    assert third.status == "completed"
    a, b = read_timeseries(ref), read_timeseries(cut)
    for key in a:
        np.testing.assert_array_equal(a[key], b[key], err_msg=key)
    with h5py.File(ref) as h1, h5py.File(cut) as h2:
        np.testing.assert_array_equal(h1["snapshots/positions"][()], h2["snapshots/positions"][()])
        np.testing.assert_array_equal(h1["snapshots/contact_pairs"][()], h2["snapshots/contact_pairs"][()])


def test_rows_after_the_last_checkpoint_are_recomputed_not_duplicated(tmp_path):
    params = SimParams(**{**TINY, "checkpoint_wall_seconds": 1e9})  # only the final checkpoint
    path = tmp_path / "run.h5"
    run_state_point(params, path, progress=False, max_steps=60)
    n_first = read_timeseries(path)["time"].shape[0]
    run_state_point(params, path, progress=False)
    ts = read_timeseries(path)
    assert ts["time"].shape[0] == 12 and n_first < 12
    assert np.all(np.diff(ts["strain"]) > 0)


def test_extending_the_strain_continues_a_completed_run(tmp_path):
    path = tmp_path / "run.h5"
    run_state_point(SimParams(**TINY), path, progress=False)
    out = run_state_point(SimParams(**{**TINY, "strain": 0.2}), path, progress=False)
    assert out.status == "completed" and out.strain >= 0.2
    assert read_timeseries(path)["strain"].shape[0] == 20


def test_rerunning_a_finished_state_point_leaves_its_file_untouched(tmp_path):
    """A sweep invoked again skips finished runs without opening them for writing (no rewritten
    attributes, no HDF5 free-space growth, no churn in committed data)."""
    path = tmp_path / "run.h5"
    first = run_state_point(SimParams(**TINY), path, progress=False)
    before = path.read_bytes()
    again = run_state_point(SimParams(**TINY), path, progress=False)
    assert path.read_bytes() == before
    assert (again.status, again.strain, again.steps) == (first.status, first.strain, first.steps)
    assert again.summary["viscosity"] == pytest.approx(first.summary["viscosity"])
    assert again.already_finished and not first.already_finished


def test_files_written_before_a_parameter_existed_resume_with_its_default(tmp_path):
    """A parameter added later (here lagged_step_control) is absent from older files' params and
    checkpoint; such a file resumes as if it held the default, and continues bit-for-bit."""
    params = SimParams(**TINY)
    ref = tmp_path / "ref.h5"
    run_state_point(params, ref, progress=False)
    old = tmp_path / "old.h5"
    run_state_point(params, old, progress=False, max_steps=40)
    with h5py.File(old, "r+") as h5:
        stored = json.loads(h5.attrs["params"])
        del stored["lagged_step_control"]
        h5.attrs["params"] = json.dumps(stored)
        del h5["checkpoint"].attrs["previous_interaction_speed"]
    assert run_state_point(params, old, progress=False).status == "completed"
    np.testing.assert_array_equal(read_timeseries(ref)["time"], read_timeseries(old)["time"])


def test_resume_refuses_another_state_point(tmp_path):
    path = tmp_path / "run.h5"
    run_state_point(SimParams(**TINY), path, progress=False, max_steps=10)
    with pytest.raises(TrajectoryFileError, match="stress"):
        run_state_point(SimParams(**{**TINY, "stress": 6.0}), path, progress=False)


def test_finished_runs_are_compressed_at_rest_and_extend_like_raw_ones(tmp_path):
    """A finished file is compressed (lossless, checkpoint kept); extending it (raw while running, then
    compressed again) gives the trajectory of a run that was never compressed."""
    from rheograph.io.hdf5 import is_compact, rewrite

    ref, packed = tmp_path / "ref.h5", tmp_path / "packed.h5"
    longer = SimParams(**{**TINY, "strain": 0.2})
    run_state_point(SimParams(**TINY), ref, progress=False)
    rewrite(ref, compressed=False)
    run_state_point(SimParams(**TINY), packed, progress=False)
    with h5py.File(packed) as h5:
        assert is_compact(h5)
    run_state_point(SimParams(**TINY), packed, progress=False)  # finished: not decompressed
    with h5py.File(packed) as h5:
        assert is_compact(h5)
    run_state_point(longer, ref, progress=False)
    run_state_point(longer, packed, progress=False)
    a, b = read_timeseries(ref), read_timeseries(packed)
    for key in a:
        np.testing.assert_array_equal(a[key], b[key], err_msg=key)


def test_an_interrupted_run_compacted_for_committing_resumes_to_the_uninterrupted_run(tmp_path):
    """``collect --compress`` also compacts interrupted runs (committed between sessions); the resume
    writes the file raw again and continues: time series and snapshots equal an uninterrupted run's."""
    from rheograph.runs.sweep_index import main as collect_main

    params = SimParams(**TINY)
    ref, cut = tmp_path / "ref" / "run.h5", tmp_path / "cut" / "run.h5"
    ref.parent.mkdir()
    cut.parent.mkdir()
    run_state_point(params, ref, progress=False)
    assert run_state_point(params, cut, progress=False, max_steps=45).status == "interrupted"
    raw_size = cut.stat().st_size
    collect_main([str(cut.parent), "--out", str(tmp_path / "index.json"), "--compress"])
    with h5py.File(cut) as h5:
        assert is_compact(h5) and h5.attrs["status"] == "interrupted"
    assert cut.stat().st_size < raw_size
    assert run_state_point(params, cut, progress=False).status == "completed"
    a, b = read_timeseries(ref), read_timeseries(cut)
    for key in a:
        np.testing.assert_array_equal(a[key], b[key], err_msg=key)
    with h5py.File(ref) as h1, h5py.File(cut) as h2:
        np.testing.assert_array_equal(h1["snapshots/positions"][()], h2["snapshots/positions"][()])


def test_a_run_respaced_and_extended_equals_a_run_at_the_coarser_spacing_from_the_start(tmp_path):
    """``python -m rheograph.runs.respace``: a finished run with snapshots every 0.03, thinned to every
    0.06 and extended at 0.06, holds the snapshots (strains, positions, targets, contact lists), time
    series and checkpoint of a run made at 0.06 from the start; a spacing that is not a whole multiple of
    the file's, and a jammed run, are refused by name, leaving the file as it was."""
    from rheograph.errors import InputError
    from rheograph.runs.respace import main as respace_main

    coarse = SimParams(**{**TINY, "snapshot_interval": 0.06, "strain": 0.2})
    ref, fine = tmp_path / "ref.h5", tmp_path / "fine.h5"
    run_state_point(coarse, ref, progress=False)
    run_state_point(SimParams(**TINY), fine, progress=False)  # every 0.03 to strain 0.12
    untouched = fine.read_bytes()
    for bad in ("0.045", "0.015", "0"):
        with pytest.raises(InputError, match=f"interval={float(bad)!r}.*whole multiple"):
            respace_main([str(fine), "--interval", bad])
    assert fine.read_bytes() == untouched
    respace_main([str(fine), "--interval", "0.06"])
    with h5py.File(fine) as h5:
        assert h5["snapshots/strain"].shape[0] == 2 and is_compact(
            h5
        )  # strains 0 and 0.06 of 0, .03, .06, .09
    assert run_state_point(coarse, fine, progress=False).status == "completed"
    with h5py.File(ref) as a, h5py.File(fine) as b:
        assert json.loads(a.attrs["params"]) == json.loads(b.attrs["params"])
        assert a["snapshots/strain"].shape[0] == 4
        for group in ("snapshots", "timeseries", "checkpoint"):
            for name in a[group]:
                np.testing.assert_array_equal(a[group][name][()], b[group][name][()], err_msg=name)
        counters = [json.loads(h5["checkpoint"].attrs["counters"]) for h5 in (a, b)]
        for c in counters:
            c.pop("cpu_seconds")  # measured, not simulated
            c.pop("peak_memory_mb")
        assert counters[0] == counters[1]
    # a batch is checked whole before any file is rewritten: a jammed run in it leaves the others alone
    jammed, other = tmp_path / "jammed.h5", tmp_path / "other.h5"
    run_state_point(SimParams(**TINY), jammed, progress=False)
    run_state_point(SimParams(**TINY), other, progress=False)
    with h5py.File(jammed, "r+") as h5:
        h5.attrs["status"] = "jammed"
    untouched = other.read_bytes()
    with pytest.raises(InputError, match="jammed"):
        respace_main([str(other), str(jammed), "--interval", "0.06"])
    assert other.read_bytes() == untouched
    with pytest.raises(InputError, match=r"files: \['.*nothing\*.h5'\] match no trajectory file"):
        respace_main([str(other), str(tmp_path / "nothing*.h5"), "--interval", "0.06"])
    assert other.read_bytes() == untouched


def test_rewrite_refuses_bad_snapshot_selections_and_leaves_no_half_file(tmp_path):
    """``rewrite(keep_snapshots=…)`` takes strictly ascending indices below the checkpoint's count and sets
    that count to the kept one (a resume then continues after them); an edit that fails, like an
    interruption or a full disk (then named in one line), leaves the original file and no temporary
    file."""
    from rheograph.errors import InputError
    from rheograph.io.hdf5 import rewrite

    path = tmp_path / "run.h5"
    run_state_point(SimParams(**TINY), path, progress=False)  # 4 snapshots: strain 0, 0.03, 0.06, 0.09
    untouched = path.read_bytes()
    for bad in ([3, 1], [1, 1], [0, 4], [-1]):
        with pytest.raises(InputError, match=r"keep_snapshots=.*strictly ascending indices in \[0, 4\)"):
            rewrite(path, keep_snapshots=bad)
    assert path.read_bytes() == untouched

    def failing_edit(h5):
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        rewrite(path, keep_snapshots=[0, 2], edit=failing_edit)
    assert path.read_bytes() == untouched and not list(tmp_path.glob("*.tmp"))

    def full_disk(h5):
        raise OSError("File write failed")  # as h5py reports it: no errno

    with pytest.raises(InputError, match=r"is the disk full or a quota reached\? .*run.h5 is unchanged"):
        rewrite(path, keep_snapshots=[0, 2], edit=full_disk)
    assert path.read_bytes() == untouched and not list(tmp_path.glob("*.tmp"))
    rewrite(path, keep_snapshots=[0, 2])
    with h5py.File(path) as h5:
        assert json.loads(h5["checkpoint"].attrs["counters"])["snapshots"] == 2
        assert h5["snapshots/strain"].shape == (2,) and 0.06 <= h5["snapshots/strain"][1] < 0.09


def test_the_compact_layout_keeps_what_the_learning_and_a_resume_need(tmp_path):
    """At rest, positions are stored to 1e-7 a, stretches as float32 and pairs as int32
    (rheograph.io.hdf5.AT_REST): against the raw file of the same run, positions move by <= 5e-8 a, the
    graphs keep every edge and contact flag with features equal to float32 round-off, targets, time series
    and the checkpoint are bit for bit the same, and the file is smaller."""
    import shutil

    from rheograph.graphs.dataset import GraphSettings, snapshot_graphs
    from rheograph.io.hdf5 import is_compact, rewrite

    raw, compact = tmp_path / "raw.h5", tmp_path / "compact.h5"
    params = SimParams(**{**TINY, "stress": 50.0})  # many contacts: overlaps of ~1e-3 a decide the flags
    run_state_point(params, raw, progress=False, max_steps=250)  # unfinished: raw, full precision
    shutil.copy(raw, compact)
    rewrite(compact, compressed=True)
    with h5py.File(raw) as a, h5py.File(compact) as b:
        assert not is_compact(a) and is_compact(b)
        assert b["snapshots/positions"].shape[0] >= 2 and b["snapshots/contact_pairs"].shape[0] > 0
        drift = np.abs(a["snapshots/positions"][()] - b["snapshots/positions"][()]).max()
        assert 0 < drift <= 0.5e-7 * (1 + 1e-6)
        np.testing.assert_array_equal(a["snapshots/contact_pairs"][()], b["snapshots/contact_pairs"][()])
        np.testing.assert_allclose(
            a["snapshots/contact_stretch"][()], b["snapshots/contact_stretch"][()], rtol=1e-7, atol=1e-30
        )
        for group in ("checkpoint", "timeseries"):
            for name in a[group]:
                np.testing.assert_array_equal(a[group][name][()], b[group][name][()], err_msg=name)
        for name in ("viscosity", "pressure", "z_mu", "z", "strain", "le_offset"):
            np.testing.assert_array_equal(a["snapshots"][name][()], b["snapshots"][name][()], err_msg=name)
    settings = GraphSettings(
        edge_features=("gap", "dx", "dy", "contact", "overlap", "lubrication", "load", "frictional"),
        graph_inputs=("log_stress",),
        min_strain=0.0,
    )
    for g_raw, g_compact in zip(snapshot_graphs(raw, settings, 0), snapshot_graphs(compact, settings, 0)):
        np.testing.assert_array_equal(g_raw.edge_index.numpy(), g_compact.edge_index.numpy())
        contact = list(settings.edge_features).index("contact")
        np.testing.assert_array_equal(g_raw.edge_attr[:, contact], g_compact.edge_attr[:, contact])
        np.testing.assert_allclose(g_raw.edge_attr.numpy(), g_compact.edge_attr.numpy(), rtol=2e-3, atol=1e-5)
        np.testing.assert_array_equal(g_raw.y_raw.numpy(), g_compact.y_raw.numpy())
    assert compact.stat().st_size < raw.stat().st_size


def test_a_state_point_already_running_elsewhere_is_refused(tmp_path):
    import subprocess
    import sys

    path = tmp_path / "run.h5"
    run_state_point(SimParams(**TINY), path, progress=False)
    holder = subprocess.Popen(
        [
            sys.executable,
            "-c",
            f"import h5py, time; f = h5py.File({str(path)!r}, 'r+'); print('open', flush=True); "
            "time.sleep(60)",
        ],
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert holder.stdout.readline().strip() == "open"
        with pytest.raises(TrajectoryFileError, match="open in another process"):
            run_state_point(SimParams(**{**TINY, "strain": 0.2}), path, progress=False)
        with pytest.raises(TrajectoryFileError, match="is a simulation writing it"):
            respace_snapshots(path, 0.06)
    finally:
        holder.kill()


def test_a_truncated_file_is_named_truncated_and_left_alone(tmp_path):
    path = tmp_path / "run.h5"
    run_state_point(SimParams(**TINY), path, progress=False)
    path.write_bytes(path.read_bytes()[:20000])
    before = path.read_bytes()
    with pytest.raises(TrajectoryFileError, match="truncated.*move it aside"):
        run_state_point(SimParams(**{**TINY, "strain": 0.2}), path, progress=False)
    assert path.read_bytes() == before


def test_resume_refuses_corrupt_and_foreign_files(tmp_path):
    junk = tmp_path / "junk.h5"
    junk.write_bytes(b"not an hdf5 file at all")
    with pytest.raises(TrajectoryFileError, match="not a readable HDF5"):
        run_state_point(SimParams(**TINY), junk, progress=False)
    foreign = tmp_path / "foreign.h5"
    with h5py.File(foreign, "w") as h5:
        h5["x"] = 1
    with pytest.raises(TrajectoryFileError, match="not a rheograph trajectory"):
        run_state_point(SimParams(**TINY), foreign, progress=False)


def test_an_interruption_between_checkpoint_delete_and_move_resumes_exactly(tmp_path):
    """The checkpoint is replaced atomically: written as checkpoint_new, the old one deleted, the new one
    moved.  A kill between delete and move leaves only checkpoint_new; the resume promotes it and the
    run ends bit-identical to the uninterrupted one."""
    params = SimParams(**TINY)
    ref = tmp_path / "ref.h5"
    run_state_point(params, ref, progress=False)
    cut = tmp_path / "cut.h5"
    assert run_state_point(params, cut, progress=False, max_steps=40).status == "interrupted"
    with h5py.File(cut, "r+") as h5:
        h5.move("checkpoint", "checkpoint_new")
    assert run_state_point(params, cut, progress=False).status == "completed"
    a, b = read_timeseries(ref), read_timeseries(cut)
    for key in a:
        np.testing.assert_array_equal(a[key], b[key], err_msg=key)


@pytest.mark.parametrize("damage", ["schema", "no_checkpoint"])
def test_a_file_of_another_schema_or_without_checkpoint_is_refused_untouched(tmp_path, damage):
    path = tmp_path / "run.h5"
    run_state_point(SimParams(**TINY), path, progress=False, max_steps=20)
    with h5py.File(path, "r+") as h5:
        if damage == "schema":
            h5.attrs["schema_version"] = 0
        else:
            del h5["checkpoint"]
    before = path.read_bytes()
    match = "schema_version 0, this rheograph writes 1" if damage == "schema" else "checkpoint is missing"
    with pytest.raises(TrajectoryFileError, match=match):
        run_state_point(SimParams(**TINY), path, progress=False)
    assert path.read_bytes() == before


@pytest.mark.parametrize(
    "text,match",
    [
        ("{not json", "not a readable rheograph index"),
        ('{"format": "other", "runs": []}', "not a rheograph index"),
    ],
)
def test_an_index_that_is_not_one_is_refused_by_name(tmp_path, text, match):
    from rheograph.errors import InputError
    from rheograph.io.index import read_index

    path = tmp_path / "index.json"
    path.write_text(text)
    with pytest.raises(InputError, match=match):
        read_index(path)


@pytest.mark.parametrize(
    "override,match",
    [
        (dict(phi=0.95), "sim.phi"),
        (dict(phi=0.0), "sim.phi"),
        (dict(stress=-1.0), "sim.stress"),
        (dict(stress=float("nan")), "sim.stress"),
        (dict(n_particles=10), "too small for the interaction cut-off"),
        (dict(disp_max=0.0), "sim.disp_max"),
        (dict(integrator="rk4"), "sim.integrator"),
        (dict(jam_intervals=2.5), "sim.jam_intervals=2.5 is invalid: expected an integer"),
        (dict(strain="abc"), "sim.strain='abc' is invalid: expected a number"),
        (dict(mu=None), "sim.mu=None is invalid: expected a number"),
        (dict(mu=True), "sim.mu=True is invalid: expected a number"),
        (
            dict(critical_load=2.0),
            "sim.critical_load=2.0 is invalid: allowed 1 \\(F_CL is the unit of force\\)",
        ),
        (dict(seed=True), "sim.seed=True is invalid: expected an integer"),
        (dict(lagged_step_control=1), "sim.lagged_step_control=1 is invalid: expected true or false"),
    ],
)
def test_bad_parameters_are_named(override, match):
    with pytest.raises(ParameterError, match=match):
        SimParams(**{**TINY, **override})


def test_unknown_parameter_is_rejected():
    with pytest.raises(ParameterError, match="unknown simulation parameter"):
        SimParams.from_mapping({**TINY, "temperature": 1.0})


DENSE = [
    (i, phi, stress) for i in ("euler", "implicit") for phi in (0.80, 0.82) for stress in (200.0, 1000.0)
]


# the densest, stiffest case of each integrator by default; the other six with -m slow
@pytest.mark.parametrize(
    "integrator, phi, stress",
    [case if case[1:] == (0.82, 1000.0) else pytest.param(*case, marks=pytest.mark.slow) for case in DENSE],
)
def test_dense_high_stress_runs_stay_finite_with_bounded_overlap(tmp_path, phi, stress, integrator):
    params = SimParams(
        integrator=integrator,
        n_particles=100,
        phi=phi,
        stress=stress,
        strain=0.05,
        output_interval=0.005,
        snapshot_interval=1.0,
        disp_max=2e-3,
        jam_intervals=10**6,
    )
    out = run_state_point(params, tmp_path / "dense.h5", progress=False, max_steps=4000)
    ts = read_timeseries(tmp_path / "dense.h5")
    assert out.status in ("completed", "interrupted")
    for key in ("shear_rate", "viscosity", "pressure", "max_overlap"):
        assert np.all(np.isfinite(ts[key])), key
    # k_n scales with the stress, so the overlap in units of the typical one, F_CL sigma/sigma0 / k_n =
    # 6 pi / 2e4 = 9.4e-4 a, does not grow with the stress; a k_n fixed at its sigma/sigma0 = 1 value
    # would give overlaps of 200-1000 typical ones here
    typical = 6 * np.pi / 2e4
    assert ts["max_overlap"].max() < 10 * typical


def test_jam_detection_ends_a_stalled_run(tmp_path):
    """A nearly rigid frictional packing above phi_J^mu at high stress stops flowing: the run ends
    as 'jammed' with the jammed rows recorded (jam_viscosity lowered to keep the test short)."""
    params = SimParams(
        n_particles=100,
        phi=0.84,
        stress=100.0,
        strain=2.0,
        jam_viscosity=2e3,
        jam_intervals=5,
        disp_max=2e-3,
        relax_tolerance=1e-3,
    )
    out = run_state_point(params, tmp_path / "jam.h5", progress=False, max_steps=60000)
    ts = read_timeseries(tmp_path / "jam.h5")
    assert out.status == "jammed", (out, ts["viscosity"][-10:])
    assert ts["jammed"][-5:].all()
    info = read_run_info(tmp_path / "jam.h5")
    assert info["status"] == "jammed"
    # the last snapshot is the arrested packing, at the strain where the run stopped; the snapshots from
    # the stalled window on are labelled jammed, earlier ones flowed; the learning keeps the jammed ones
    # at any strain (an arrested packing is no start-up transient) and marks exactly those
    from rheograph.graphs.dataset import GraphSettings, snapshot_graphs
    from rheograph.io.hdf5 import jammed_snapshots

    with h5py.File(tmp_path / "jam.h5") as h5:
        snap_strain, z_mu = h5["snapshots/strain"][()], h5["snapshots/z_mu"][()]
    assert snap_strain[-1] == pytest.approx(info["strain"], abs=1e-3)
    jammed = jammed_snapshots("jammed", snap_strain, ts["strain"], params.jam_intervals)
    assert jammed[-1] and z_mu[-1] > 0
    # the initial packing is part of the stalled window exactly when the flow never got going (this
    # dense packing stalls from its first interval: 6 rows, the window of 5 intervals)
    assert jammed[0] == (ts["strain"].size <= params.jam_intervals + 1)
    assert not jammed_snapshots("completed", snap_strain, ts["strain"], params.jam_intervals).any()
    graphs = snapshot_graphs(tmp_path / "jam.h5", GraphSettings(min_strain=10.0), run_id=0)
    assert len(graphs) == jammed.sum() and all(bool(g.jammed) for g in graphs)
    assert graphs[-1].strain.item() == pytest.approx(snap_strain[-1])


def test_flowing_state_is_not_flagged_jammed(tmp_path):
    out = run_state_point(SimParams(**TINY), tmp_path / "flow.h5", progress=False)
    assert out.status == "completed"
    assert not read_timeseries(tmp_path / "flow.h5")["jammed"].any()


def test_sigterm_checkpoints_then_exits_and_the_run_resumes(tmp_path):
    """A SIGTERM (e.g. SLURM pre-emption) mid-run: checkpoint, clean close, non-zero exit; resume later."""
    import signal
    import subprocess
    import sys
    import time

    path = tmp_path / "run.h5"
    code = (
        "from rheograph.runs.runner import run_state_point\n"
        "from rheograph.sim.params import SimParams\n"
        f"run_state_point(SimParams(n_particles=64, phi=0.74, stress=5.0, strain=50.0), {str(path)!r},"
        " progress=False)\n"
    )
    proc = subprocess.Popen([sys.executable, "-c", code])
    deadline = time.time() + 120
    while time.time() < deadline and not path.exists():
        time.sleep(0.2)
    time.sleep(2.0)
    proc.send_signal(signal.SIGTERM)
    assert proc.wait(timeout=60) == 128 + signal.SIGTERM
    info = read_run_info(path)
    assert info["status"] == "interrupted" and info["strain"] > 0
    out = run_state_point(
        SimParams(n_particles=64, phi=0.74, stress=5.0, strain=info["strain"] + 0.01), path, progress=False
    )
    assert out.status == "completed"


def test_jam_window_counts_the_window_total_not_single_rows():
    from rheograph.runs.runner import first_jammed_row

    stress, eta_jam = 10.0, 1e5
    # flowing at eta = 1e3: rows of 0.01 strain every 1 time unit -> never jammed
    t = np.arange(50.0)
    assert first_jammed_row(t, 0.01 * t, stress, eta_jam, 10) is None
    # creeping with single stalled rows (each alone above eta_jam) but flowing on average: not jammed
    d_strain = np.where(np.arange(49) % 3 == 0, 1e-6, 0.01)
    strain = np.concatenate([[0.0], np.cumsum(d_strain)])
    assert first_jammed_row(t, strain, stress, eta_jam, 10) is None
    # then the strain stops: jammed once the 10-row window's total apparent viscosity exceeds eta_jam
    strain = np.concatenate([0.01 * np.arange(20.0), np.full(30, 0.19)])
    row = first_jammed_row(t, strain, stress, eta_jam, 10)
    window_time, window_strain = t[row] - t[row - 10], strain[row] - strain[row - 10]
    assert stress * window_time > eta_jam * window_strain
    assert stress * (t[row - 1] - t[row - 11]) <= eta_jam * (strain[row - 1] - strain[row - 11])


def test_snapshots_are_labelled_jammed_from_the_first_row_of_the_detectors_window():
    """The run ends at the row where the detector fires; its window holds the last jam_intervals
    intervals, i.e. starts jam_intervals rows earlier.  A snapshot taken inside the window's first
    interval shows the stalled packing (jammed); one taken before the window flowed."""
    from rheograph.io.hdf5 import jammed_snapshots
    from rheograph.runs.runner import first_jammed_row

    stress, eta_jam, intervals = 10.0, 1e5, 10
    t = np.arange(40.0)
    strain = np.concatenate([0.01 * np.arange(20.0), 0.19 + 1e-6 * np.arange(1.0, 21.0)])
    end = first_jammed_row(t, strain, stress, eta_jam, intervals)
    series = strain[: end + 1]  # the run's rows when it ends
    start = series[end - intervals]  # first row of the stalled window
    snapshots = np.array([start - 1e-4, start, 0.5 * (start + series[end - intervals + 1]), series[-1]])
    labels = jammed_snapshots("jammed", snapshots, series, intervals)
    np.testing.assert_array_equal(labels, [False, True, True, True])
    assert not jammed_snapshots("completed", snapshots, series, intervals).any()


DATA = Path(__file__).resolve().parents[1] / "data"


def test_default_jam_window_replayed_on_the_committed_runs_flags_only_the_jammed_ones():
    """docs/validation/speed.md: the default window (10 rows), replayed on every committed trajectory, flags
    the phi = 0.80 runs that shear-jammed and none of the flowing ones (phi up to 0.80, sigma up to 200,
    eta_r up to ~800), whatever window each run was made with."""
    from rheograph.runs.runner import first_jammed_row

    defaults = SimParams.defaults()
    flagged, jammed, flowing = set(), set(), 0
    for path in sorted(DATA.rglob("*.h5")):
        try:
            with h5py.File(path) as h5:
                if "timeseries" not in h5:
                    continue
                stress = json.loads(h5.attrs["params"])["stress"]
        except BlockingIOError:  # locked by a simulation writing it right now: not a finished result
            continue
        ts = read_timeseries(path)
        row = first_jammed_row(
            ts["time"], ts["strain"], stress, defaults["jam_viscosity"], defaults["jam_intervals"]
        )
        name = path.parent.name
        flagged |= {name} if row is not None else set()
        jammed |= {name} if read_run_info(path)["status"] == "jammed" else set()
        flowing += row is None
    assert flagged == jammed
    assert {"N400_phi0.8_s50_seed1_d0.002_implicit", "N400_phi0.8_s200_seed1_d0.002_implicit"} <= jammed
    assert flowing >= 30


def test_an_area_fraction_above_jamming_is_refused_by_name_not_relaxed_for_ever():
    """Above random close packing no overlap-free start exists: the relaxation gives up with a message
    naming sim.phi and sim.relax_tolerance (a bounded number of iterations here)."""
    from rheograph.errors import InputError
    from rheograph.sim.init_config import random_configuration

    params = SimParams(**{**TINY, "phi": 0.86})
    with pytest.raises(InputError, match=r"sim\.phi: could not relax .* 0\.86.*sim\.relax_tolerance"):
        random_configuration(
            *params.species_counts(), params.size_ratio, params.box_length(), 1, max_iterations=2000
        )
    positions, _ = random_configuration(
        *SimParams(**TINY).species_counts(), 1.4, SimParams(**TINY).box_length(), 1
    )
    assert np.isfinite(positions).all()  # the same call relaxes a flowing area fraction


def test_read_checkpoint_gives_the_state_a_resume_continues_from(tmp_path):
    """``read_checkpoint`` (analyses that continue a run without extending it) returns the parameters and
    every array and scalar of the state the writer resumes from (``TrajectoryFile.open_existing``, on a
    copy), and leaves the file as it was."""
    import shutil

    from rheograph.io.hdf5 import TrajectoryFile, read_checkpoint
    from rheograph.sim.integrator import SimState

    path, copy = tmp_path / "run.h5", tmp_path / "copy.h5"
    run_state_point(SimParams(**TINY), path, progress=False)
    shutil.copy(path, copy)
    before = path.read_bytes()
    params, state = read_checkpoint(path)
    assert path.read_bytes() == before
    writer = TrajectoryFile(copy, params)
    resumed, _ = writer.open_existing()
    writer.close()
    for name in SimState.ARRAYS:
        np.testing.assert_array_equal(getattr(state, name), getattr(resumed, name), err_msg=name)
    for name in SimState.SCALARS:
        assert getattr(state, name) == getattr(resumed, name), name
    assert state.steps > 0 and params.to_dict() == SimParams(**TINY).to_dict()
