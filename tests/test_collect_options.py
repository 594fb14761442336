"""The data collection's options: ``sensor_noise`` and ``qdd_source``, the sensor standard deviations stored with
the data, the reuse check for files written before the options existed, and :func:`study_data`'s error paths. The
collections here are a few seconds of simulation (well under a second each)."""

from __future__ import annotations

from dataclasses import asdict, replace
from pathlib import Path

import numpy as np
import pytest

from cascgp.data import DynamicsData


pytest.importorskip("jaco_env.excitation")

from cascgp_experiments.collect import CollectConfig, collect, same_collection

#: A tiny collection: 1 training and 1 test motion of 1.5 s after a 0.2 s warm-up.
# Under the idealised signal: the options below are compared with their noise alone (the jaco2 pipeline's own
# behaviour is tested in test_signal_pipeline).
TINY = CollectConfig(n_subsets=1, subset_seconds=1.5, n_test=1, test_seconds=1.5, warmup_seconds=0.2,
                     sensor_pipeline="ideal")


def test_collect_config_rejects_unknown_options() -> None:
    with pytest.raises(ValueError, match="sensor_noise"):
        CollectConfig(sensor_noise="low")
    with pytest.raises(ValueError, match="qdd_source"):
        CollectConfig(qdd_source="central")
    from cascgp_experiments.collect import make_env

    with pytest.raises(ValueError, match="sensor_noise"):
        make_env(100.0, 0.8, "off")


@pytest.mark.parametrize("noise", ["default", "none"])
def test_the_stored_sensor_std_is_that_of_the_collection_env(noise) -> None:
    from cascgp_experiments.collect import make_env, sensor_std

    env = make_env(100.0, 0.8, noise)
    try:
        sn = env.unwrapped.sensor_noise
        assert sensor_std(noise) == {"q_std": sn.q_std, "qd_std": sn.qd_std, "tau_std": sn.tau_std}
    finally:
        env.close()


def test_same_collection_accepts_files_from_before_the_options() -> None:
    old = {k: v for k, v in asdict(CollectConfig()).items() if k not in ("sensor_noise", "qdd_source")}
    assert same_collection(old, CollectConfig())
    assert not same_collection(old, CollectConfig(sensor_noise="none"))
    assert not same_collection(old, CollectConfig(qdd_source="true"))
    assert same_collection(asdict(CollectConfig(sensor_noise="none")), CollectConfig(sensor_noise="none"))
    assert not same_collection(None, CollectConfig())


@pytest.fixture(scope="module")
def arms(tmp_path_factory) -> dict[str, tuple[DynamicsData, DynamicsData]]:
    root = tmp_path_factory.mktemp("arms")
    out = {}
    for name, cfg in (("noisy", TINY), ("noiseless", replace(TINY, sensor_noise="none")),
                      ("true", replace(TINY, sensor_noise="none", qdd_source="true"))):
        train, test, info = collect(root / name, cfg, workers=1)
        assert not info["reused"]
        out[name] = (train, test)
    return out


def test_noiseless_arm_is_the_same_motion_without_the_noise(arms) -> None:
    (n_tr, _), (z_tr, _) = arms["noisy"], arms["noiseless"]
    assert z_tr.meta["collection"]["sensor_noise"] == "none"
    assert n_tr.meta["collection"]["sensor_noise"] == "default"
    # Same motion: the differences are the sensor noise (q 5e-4 rad, qd 5e-3 rad/s, tau 0.1 N m), no drift.
    for key, std in (("q", 5e-4), ("qd", 5e-3), ("tau", 0.1)):
        d = getattr(z_tr, key) - getattr(n_tr, key)
        assert 0.5 * std < d.std() < 1.5 * std and np.abs(d).max() < 6 * std
    np.testing.assert_array_equal(z_tr.t, n_tr.t)
    # Each file stores the sensor standard deviations it was recorded with; they match the differences above.
    assert n_tr.meta["sensor_std"] == {"q_std": 5e-4, "qd_std": 5e-3, "tau_std": 0.1}
    assert z_tr.meta["sensor_std"] == {"q_std": 0.0, "qd_std": 0.0, "tau_std": 0.0}


def test_true_qdd_arm_uses_the_simulator_accelerations(arms) -> None:
    (z_tr, z_te), (t_tr, t_te) = arms["noiseless"], arms["true"]
    for z, t in ((z_tr, t_tr), (z_te, t_te)):
        for key in ("q", "qd", "tau", "t"):
            np.testing.assert_array_equal(getattr(z, key), getattr(t, key))
        assert "true joint accelerations" in t.meta["qdd_source"]
        assert "Savitzky" in z.meta["qdd_source"]
        # the filtered estimate differs from the truth by the RMSE recorded in the meta
        rmse = np.sqrt(np.mean((z.qdd - t.qdd) ** 2, axis=0))
        np.testing.assert_allclose(rmse, z.meta["qdd_error"]["est_rmse"], rtol=1e-9)


def test_collect_reuses_files_written_before_the_options(arms, tmp_path: Path) -> None:
    train, test = arms["noisy"]
    for split, d in (("train", train), ("test", test)):
        meta = dict(d.meta)
        meta["collection"] = {k: v for k, v in meta["collection"].items() if k not in ("sensor_noise", "qdd_source")}
        replace(d, meta=meta).save(tmp_path / f"jaco_{split}.npz")
    assert collect(tmp_path, TINY, workers=1)[2]["reused"]


def test_a_collection_of_other_settings_is_refused_unless_forced(arms, tmp_path: Path) -> None:
    """``replace_other=False`` (``cascgp collect``): files of other settings are refused, named and left as they
    were; ``force`` replaces them; the default (the study) replaces them."""
    from cascgp_experiments.collect import OtherCollectionError

    train, test = arms["noisy"]
    for split, d in (("train", train), ("test", test)):
        d.save(tmp_path / f"jaco_{split}.npz")
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    other = replace(TINY, seed=TINY.seed + 1)
    refused = r"other settings \(jaco_train.npz: seed 0 \(now 1\)\); pass --force"
    with pytest.raises(OtherCollectionError, match=refused):
        collect(tmp_path, other, workers=1, replace_other=False)
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before
    lone = tmp_path / "lone"  # one file of another collection (the other missing) is refused too
    lone.mkdir()
    train.save(lone / "jaco_train.npz")
    with pytest.raises(OtherCollectionError, match="jaco_train.npz: seed 0"):
        collect(lone, other, workers=1, replace_other=False)
    assert [p.name for p in lone.iterdir()] == ["jaco_train.npz"]
    assert collect(tmp_path, TINY, workers=1, replace_other=False)[2]["reused"]  # the same settings: reused
    assert not collect(tmp_path, other, workers=1, replace_other=False, force=True)[2]["reused"]


def test_study_data_rejects_collection_options_with_a_folder(tmp_path: Path) -> None:
    from cascgp_experiments.collect import study_data

    with pytest.raises(ValueError, match="new collection"):
        study_data(tmp_path, tmp_path, sensor_noise="none")
    with pytest.raises(ValueError, match="preset"):
        study_data(None, tmp_path, preset="huge")


def test_qdd_filter_follows_the_pipeline_unless_given() -> None:
    assert CollectConfig().smoothing.causal  # the default pipeline is "jaco2"
    assert not CollectConfig(sensor_pipeline="ideal").smoothing.causal
    assert CollectConfig(sensor_pipeline="jaco2").smoothing.causal
    assert not CollectConfig(sensor_pipeline="jaco2", qdd_filter="centred").smoothing.causal
    assert CollectConfig(qdd_filter="causal").smoothing.causal
    assert CollectConfig().smoothing.window == CollectConfig().savgol_window
    with pytest.raises(ValueError, match="qdd_filter"):
        CollectConfig(qdd_filter="zero-phase")
    old = {k: v for k, v in asdict(CollectConfig()).items() if k != "qdd_filter"}
    assert same_collection(old, CollectConfig()) and not same_collection(old, CollectConfig(qdd_filter="causal"))


def test_causal_qdd_arm_differs_from_the_centred_only_in_qdd(arms, tmp_path: Path) -> None:
    train, _ = collect(tmp_path / "causal", replace(TINY, qdd_filter="causal"), workers=1)[:2]
    ref = arms["noisy"][0]
    for name in ("q", "qd", "tau", "t"):
        np.testing.assert_array_equal(getattr(train, name), getattr(ref, name))
    assert not np.array_equal(train.qdd, ref.qdd)
    assert "causal Savitzky-Golay" in train.meta["qdd_source"]
    # the causal estimate at a row uses no later row: recomputing it from the rows up to there gives the same value
    k = 60
    from cascgp.derivatives import differentiate

    head = differentiate(train.t[:k], train.qd[:k], train.segment[:k], replace(TINY, qdd_filter="causal").smoothing)
    np.testing.assert_array_equal(head, train.qdd[:k])


def test_pipeline_factor_names_are_accepted_and_bad_ones_refused() -> None:
    cfg = CollectConfig(sensor_pipeline="ideal+skew+torque")
    assert not cfg.smoothing.causal  # only "jaco2" makes the q̈ filter causal by default
    with pytest.raises(ValueError, match="sensor_pipeline: expected one of .*'skew', 'velocity', 'torque'"):
        CollectConfig(sensor_pipeline="ideal+inertials")
    with pytest.raises(ValueError, match="sensor_pipeline"):
        CollectConfig(sensor_pipeline=None)  # type: ignore[arg-type]


def test_link_inertials_follow_the_pipeline_unless_given(tmp_path: Path) -> None:
    assert CollectConfig().nominal_link_inertials == "kinova"  # the default pipeline is "jaco2"
    assert CollectConfig(sensor_pipeline="ideal").nominal_link_inertials == "dm_control"
    assert CollectConfig(sensor_pipeline="jaco2", link_inertials="dm_control").nominal_link_inertials == "dm_control"
    with pytest.raises(ValueError, match="link_inertials: expected None or one of"):
        CollectConfig(link_inertials="urdf")
    old = {k: v for k, v in asdict(CollectConfig()).items() if k != "link_inertials"}
    assert same_collection(old, CollectConfig()) and not same_collection(old, CollectConfig(link_inertials="kinova"))
    from cascgp_experiments.collect import make_env

    for option, expected in ((None, "dm_control"), ("kinova", "kinova")):
        env = make_env(100.0, 0.8, "default", "ideal", option)
        assert env.unwrapped.link_inertials == expected
        env.close()
    # Only the physics changes: the same commands, another arm, other torques.
    heavy, _ = collect(tmp_path / "kinova", replace(TINY, link_inertials="kinova"), workers=1)[:2]
    light, _ = collect(tmp_path / "dm", TINY, workers=1)[:2]
    assert heavy.meta["collection"]["link_inertials"] == "kinova"
    assert np.abs(heavy.tau - light.tau).max() > 0.1


def test_nominal_urdf_follows_the_recorded_arm() -> None:
    from jaco_env import nominal_urdf

    from cascgp_experiments.collect import nominal_urdf_for

    assert nominal_urdf_for({"collection": asdict(CollectConfig())}) == nominal_urdf("kinova")
    assert nominal_urdf_for({"collection": asdict(TINY)}) == nominal_urdf("dm_control")
    assert nominal_urdf_for({"collection": asdict(replace(TINY, link_inertials="kinova"))}) == nominal_urdf("kinova")
    # A file from before the options was recorded under "ideal" with dm_control's inertials.
    old = {k: v for k, v in asdict(CollectConfig()).items() if k not in ("sensor_pipeline", "link_inertials")}
    assert nominal_urdf_for({"collection": old}) == nominal_urdf("dm_control")
    with pytest.raises(ValueError, match=r"meta\['collection'\]"):
        nominal_urdf_for({})


def test_collect_command_prints_a_summary_and_reuses_its_files(tmp_path: Path, capsys) -> None:
    """``cascgp collect`` names each file with its size, then says whether it collected or reused them."""
    from cascgp_experiments.cli.collect import main

    args = ["--smoke", "--out", str(tmp_path), "--workers", "1"]
    main(args)
    first = capsys.readouterr().out.splitlines()
    train = DynamicsData.load(tmp_path / "jaco_train.npz")
    assert first[0] == (f"{tmp_path / 'jaco_train.npz'}: {train.n_samples} samples, {len(train.segments)} "
                        f"motion(s), 6 joints, dt {train.dt:g} s")
    assert first[1].startswith(f"{tmp_path / 'jaco_test.npz'}: ") and first[2].startswith("collected in ")
    # the run's record: one job per motion, each timed, with the versions and the machine
    from cascgp.io import read_json
    from cascgp_experiments.parallel_bench import job_stats

    test = DynamicsData.load(tmp_path / "jaco_test.npz")
    n_motions = len(train.segments) + len(test.segments)
    run = read_json(tmp_path / "collection_run.json")
    jobs = run["jobs"]
    assert (jobs["n_jobs"], jobs["workers"], jobs["backend"]) == (n_motions, 1, "in-process")
    assert len(jobs["job_seconds"]) == n_motions and all(s > 0 for s in jobs["job_seconds"])
    assert jobs["job_seconds_sum"] <= jobs["wall_s"] <= run["wall_s"]
    assert run["provenance"]["versions"]["numpy"] == np.__version__ and run["provenance"]["machine"]["cpus"]
    assert f"({n_motions} motions as jobs on 1 worker(s), in-process; the longest" in first[2]
    assert job_stats("scripts.collect_jaco_data", tmp_path)[0]["n_jobs"] == n_motions  # bench_parallel's row
    main(args)
    again = capsys.readouterr().out.splitlines()
    assert again[:2] == first[:2] and again[2].startswith(f"reused the files in {tmp_path}")
    assert read_json(tmp_path / "collection_run.json") == run  # a reuse leaves the record of the collection
