"""Bad settings are refused before any work: the library's settings classes raise errors naming the field, and the
commands exit with status 2 and a one-line message naming the option, writing nothing."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from tests.conftest import write_tiny_ias

from cascgp.checks import check_count, check_positive
from cascgp.learning import RetrainConfig
from cascgp_experiments.collect import CollectConfig
from cascgp_experiments.study import PRESETS, Settings
from cascgp_experiments.transfer import TransferConfig


def test_check_count_and_check_positive() -> None:
    assert check_count(3, "n") == 3 and type(check_count(np.int64(3), "n")) is int
    assert check_count(0, "seed", minimum=0) == 0 and check_count(None, "k", optional=True) is None
    for bad in (0, -1, 1.0, True, "2", None):
        with pytest.raises(ValueError, match=r"^n: expected an integer >= 1, got "):
            check_count(bad, "n")
    with pytest.raises(ValueError, match=r"^k: expected None or an integer >= 2, got 1$"):
        check_count(1, "k", minimum=2, optional=True)
    assert check_positive(2, "rate_hz") == 2.0 and type(check_positive(np.float32(0.5), "r")) is float
    assert check_positive(0, "warmup", zero=True) == 0.0
    with pytest.raises(ValueError, match=r"^warmup: expected a finite number >= 0 \(s\), got -1$"):
        check_positive(-1, "warmup", "s", zero=True)
    for bad in (0, -1.0, float("nan"), float("inf"), True, "1"):
        with pytest.raises(ValueError, match=r"^rate_hz: expected a finite number > 0 \(Hz\), got "):
            check_positive(bad, "rate_hz", "Hz")


@pytest.mark.parametrize("field, value, message", [
    ("seed", -1, "seed: expected an integer >= 0"),
    ("rate_hz", 0.0, "rate_hz: expected a finite number > 0"),
    ("cap", 1, "cap: expected an integer >= 2"),
    ("restarts", 1.5, "restarts: expected an integer >= 1"),
])
def test_retrain_config_refuses_bad_fields(field, value, message) -> None:
    with pytest.raises(ValueError, match=message):
        RetrainConfig(**{field: value})


def test_gp_fit_config_refuses_a_negative_seed() -> None:
    from cascgp.gp import GPFitConfig

    with pytest.raises(ValueError, match="^seed: expected an integer >= 0, got -1$"):
        GPFitConfig(seed=-1)


@pytest.mark.parametrize("field", ["grad_tol", "rel_tol", "noise_floor", "jitter_max", "init_spread", "drop_margin",
                                   "stall_tol", "screen_rel_tol"])
@pytest.mark.parametrize("bad", [-1e-3, float("nan"), float("inf"), True, "0.1", None])
def test_gp_fit_config_refuses_bad_tolerances(field, bad) -> None:
    from cascgp.gp import GPFitConfig

    with pytest.raises(ValueError, match=rf"^{field}: expected a finite number >= 0, got "):
        GPFitConfig(**{field: bad})
    for good in (0, np.float32(0.25), np.int64(1)):  # stored as Python floats: the config saves as JSON
        v = getattr(GPFitConfig(**{field: good}), field)
        assert type(v) is float and v == float(good)


def test_a_fit_bounds_the_start_spread() -> None:
    """Beyond 20 log units a start's kernel is numerically constant; 1e308 overflowed NumPy's uniform draw. The
    bound is the fit's (a config, e.g. a saved model's, may hold more), checked before anything changes."""
    from cascgp.gp import GPBank, GPFitConfig

    rng = np.random.default_rng(0)
    X, y = rng.normal(size=(12, 2)), rng.normal(size=12)
    assert GPBank(GPFitConfig(init_spread=20, n_restarts=2, max_iter=3)).fit([X], [y]).fitted
    for bad in (20.5, 1e308):
        bank = GPBank(GPFitConfig(init_spread=bad))
        with pytest.raises(ValueError, match=r"^config.init_spread: expected at most 20.0 \(log units\) for a fit"):
            bank.fit([X], [y])
        assert not bank.fitted and bank.config.init_spread == bad


def test_retrain_config_keeps_python_numbers() -> None:
    r = RetrainConfig(seed=np.int64(2), rate_hz=np.float64(5), cap=np.int32(100), restarts=np.int64(1))
    assert [type(v) for v in (r.seed, r.rate_hz, r.cap, r.restarts)] == [int, float, int, int]


@pytest.mark.parametrize("field, value, message", [
    ("attempts", 0, "attempts: expected an integer >= 1"),
    ("payload_mass", 0.2, r"payload_mass \(total in the hand\) must be in \[0.351"),
    ("payload_mass", "1.2", "payload_mass .* must be a real number"),
    ("tasks", ("front", "nowhere"), "unknown task 'nowhere'"),
    ("tasks", (), "tasks: expected a non-empty sequence of distinct names"),
    ("tasks", ("front", "front"), "tasks: expected a non-empty sequence of distinct names"),
    ("controllers", "rbd", "controllers: expected a non-empty sequence of distinct names"),
    ("controllers", ("rbd", "rbd"), "controllers: expected a non-empty sequence of distinct names"),
    ("controllers", (["rbd"],), "controllers: expected a non-empty sequence of distinct names"),
    ("n_marbles", 61, "n_marbles: expected at most 60"),
    ("controllers", ("pd", "sp-sideways"), "unknown controller 'sp-sideways'"),
    ("seed", -2, "seed: expected an integer >= 0"),
    ("cap", 1, "cap: expected an integer >= 2"),
    ("rate_hz", float("nan"), "rate_hz: expected a finite number > 0"),
    ("fit_seed_offset", -1, "fit_seed_offset: expected an integer >= 0"),
    ("sensor_pipeline", "real", "sensor_pipeline: expected"),
])
def test_transfer_config_refuses_bad_fields(field, value, message) -> None:
    with pytest.raises((ValueError, TypeError), match=message):
        TransferConfig(**{field: value})


def test_transfer_config_stores_json_types_and_round_trips() -> None:
    """Names as tuples, numbers as Python ints and floats (its dict keys the job cache), and frozen: what was
    checked cannot change afterwards."""
    cfg = TransferConfig(controllers=["pd", "rbd"], tasks=["front"], payload_mass=1, rate_hz=np.float64(10),
                         seed=np.int64(4))
    assert cfg.controllers == ("pd", "rbd") and cfg.tasks == ("front",)
    d = cfg.to_dict()
    assert (type(d["payload_mass"]), type(d["rate_hz"]), type(d["seed"])) == (float, float, int)
    assert TransferConfig.from_dict(d) == cfg
    assert TransferConfig().to_dict()["controllers"] == list(TransferConfig().controllers)
    with pytest.raises(AttributeError):
        cfg.cap = 0  # type: ignore[misc]


@pytest.mark.parametrize("field, value, message", [
    ("n_subsets", 0, "n_subsets: expected an integer >= 1"),
    ("subset_seconds", 0.0, r"subset_seconds: expected a finite number > 0 \(s\)"),
    ("rate_hz", "100", r"rate_hz: expected a finite number > 0 \(Hz\)"),
    ("payload_mass", 0.1, r"payload_mass must be in \[0.200, 1.600\] kg"),
    ("seed", -1, "seed: expected an integer >= 0"),
    ("warmup_seconds", "2", r"warmup_seconds: expected a finite number >= 0 \(s\)"),
])
def test_collect_config_refuses_bad_fields(field, value, message) -> None:
    with pytest.raises((ValueError, TypeError), match=message):
        CollectConfig(**{field: value})


@pytest.mark.parametrize("field, value, message", [
    ("collection", "huge", "collection: expected one of"),
    ("grid", (), "grid: expected a non-empty, strictly ascending"),
    ("grid", (2.0, 1.0), "grid: expected a non-empty, strictly ascending"),
    ("grid", (0.0, 1.0), "grid: expected a non-empty, strictly ascending"),
    ("grid", "1,2", "grid: expected a non-empty, strictly ascending"),
    ("grid", (1.0, 61.0), "grid: expected seconds of data at most the training subsets' 60 s"),
    ("sarcos_grid", (1.0, float("nan")), "sarcos_grid: expected a strictly ascending"),
    ("n_subsets", 0, "n_subsets: expected an integer >= 1"),
    ("n_subsets", 11, "n_subsets: expected at most the 'full' collection's 10 training subsets"),
    ("n_restarts", 0, "n_restarts: expected an integer >= 1"),
    ("iter_n", 1, "iter_n: expected an integer >= 2"),
    ("seed", -1, "seed: expected an integer >= 0"),
    ("test_hz", 0, "test_hz: expected a finite number > 0"),
    ("audit_fraction", 1.5, r"audit_fraction: expected a number in \[0, 1\]"),
    ("warm_start", 1, "warm_start: expected True or False"),
])
def test_study_settings_refuse_bad_fields(field, value, message) -> None:
    with pytest.raises(ValueError, match=message):
        Settings(**{field: value})


def test_collect_config_stores_python_numbers() -> None:
    c = CollectConfig(n_subsets=np.int64(2), seed=np.int32(1), subset_seconds=np.float32(12), payload_mass=1)
    assert [type(c.n_subsets), type(c.seed), type(c.subset_seconds), type(c.payload_mass)] == [int, int, float, float]


def test_study_settings_store_tuples_and_python_numbers() -> None:
    st = Settings(grid=[1.0, 2.0], sarcos_grid=[], n_subsets=np.int64(2), test_hz=10)
    assert st.grid == (1.0, 2.0) and st.sarcos_grid == () and type(st.n_subsets) is int
    assert type(st.test_hz) is float
    for name, preset in PRESETS.items():
        assert [type(preset.n_subsets), type(preset.seed), type(preset.test_hz), type(preset.grid)] == \
            [int, int, float, tuple], name


def test_study_max_seconds_below_the_sarcos_grid_skips_sarcos(tmp_path: Path, monkeypatch, capsys) -> None:
    """``--max-seconds`` below every SARCOS grid point leaves no SARCOS part: said, not an error."""
    import cascgp_experiments.cli.study as cli

    seen: dict = {}

    def fake_run_study(out, st, **kw):
        seen.update(kw, settings=st)
        return {"meta": {"timings": {}}}

    monkeypatch.setattr(cli, "run_study", fake_run_study)
    monkeypatch.setattr(cli, "limit_threads", lambda n=1: None)
    write_tiny_ias(tmp_path / "x.mat")
    cli.main(["--out", str(tmp_path / "o"), "--grid", "0.5", "--max-seconds", "0.5", "--sarcos",
              str(tmp_path / "x.mat"), "--workers", "1"])
    assert seen["settings"].grid == (0.5,) and seen["settings"].sarcos_grid == ()
    assert "below every SARCOS grid point: the SARCOS part is skipped" in capsys.readouterr().err


def test_refused_study_prints_its_error_alone(tmp_path: Path, monkeypatch, capsys) -> None:
    """The SARCOS part's note comes after every check: a refused command prints only its error."""
    import cascgp_experiments.cli.study as cli

    monkeypatch.setattr(cli, "default_sarcos", lambda: None)  # as an installed wheel without $CASCGP_SARCOS
    with pytest.raises(SystemExit) as exc:
        cli.main(["--out", str(tmp_path / "o"), "--smoke", "--workers", "0"])
    err = capsys.readouterr().err
    assert exc.value.code == 2 and "--workers: expected an integer >= 1, got 0" in err
    assert "the SARCOS part is skipped" not in err and not (tmp_path / "o").exists()


@pytest.mark.parametrize("command, argv, message", [
    ("transfer", ["--cap", "1"], "--cap: expected an integer >= 2, got 1"),  # failed after the first episode
    ("transfer", ["--restarts", "0"], "--restarts: expected an integer >= 1, got 0"),
    # a typo's 100000000 filled the memory (attempts) or failed in every job's memory plan (restarts)
    ("transfer", ["--attempts", "100000000"], "--attempts: expected at most 1000 per task, got 100000000"),
    ("transfer", ["--restarts", "100000000"], "--restarts: expected at most 1000 starts per GP, got 100000000"),
    ("study", ["--restarts", "100000000"], "--restarts: expected at most 1000 starts per GP, got 100000000"),
    ("sarcos", ["--restarts", "1001", "--sarcos", "x.mat"], "--restarts: expected at most 1000 starts per GP"),
    ("fit", ["--data", "x.csv", "--model", "np-inward", "--restarts", "1001"],
     "--restarts: expected at most 1000 starts per GP, got 1001"),
    # ignored without a word
    ("transfer", ["--video-controller", "rbd"], "--video-controller: chooses the learner of --video's clips"),
    ("study", ["--no-sarcos", "--sarcos", "x.mat"], "--sarcos: the SARCOS part is skipped (--no-sarcos)"),
    # an empty list ran the default experiment
    ("transfer", ["--controllers", ""], "--controllers: unknown controller ''"),
    ("transfer", ["--tasks", ""], "--tasks: unknown task ''"),
    ("transfer", ["--attempts", "0"], "--attempts: expected an integer >= 1, got 0"),
    ("transfer", ["--seed", "-2"], "--seed: expected an integer >= 0, got -2"),
    ("transfer", ["--rate", "0"], "--rate: expected a finite number > 0 (Hz), got 0.0"),
    ("transfer", ["--payload", "-1"], "--payload (total in the hand) must be in [0.351, 1.600] kg, got -1.0"),
    ("transfer", ["--tasks", "front,nowhere"], "--tasks: unknown task 'nowhere'"),
    ("transfer", ["--controllers", "pd,sp-sideways"], "--controllers: unknown controller 'sp-sideways'"),
    ("transfer", ["--controllers", "pd,pd"], "--controllers: expected a non-empty sequence of distinct names"),
    ("transfer", ["--workers", "0"], "--workers: expected an integer >= 1, got 0"),
    ("study", ["--restarts", "0"], "--restarts: expected an integer >= 1, got 0"),
    ("study", ["--subsets", "0"], "--subsets: expected an integer >= 1, got 0"),
    ("study", ["--subsets", "11"], "--subsets: expected at most the 'full' collection's 10 training subsets, got 11"),
    ("study", ["--seed", "-1"], "--seed: expected an integer >= 0, got -1"),
    ("study", ["--models", ","], "--models: no name; expected names from"),
    ("study", ["--models", "np-inward,np-sideways"], "--models: unknown ['np-sideways']; expected names from"),
    ("study", ["--grid", "1,a"], "--grid: expected comma-separated seconds of data (e.g. 1,2,5), got '1,a'"),
    ("study", ["--grid", "3,1"], "--grid: expected a non-empty, strictly ascending sequence of seconds > 0"),
    ("study", ["--quick", "--grid", "1,20"], "--grid: expected seconds of data at most the training subsets' 12 s"),
    ("study", ["--grid", "5,1", "--max-seconds", "3"], "--grid: expected a non-empty, strictly ascending"),
    ("study", ["--grid", "1,nan", "--max-seconds", "5"], "--grid: expected a non-empty, strictly ascending"),
    ("collect", ["--seed", "-1"], "--seed: expected an integer >= 0, got -1"),
    ("collect", ["--smoke", "--payload-mass", "5"], "--payload-mass must be in [0.200, 1.600] kg, got 5.0"),
    ("sarcos", ["--restarts", "0", "--sarcos", "x.mat"], "--restarts: expected an integer >= 1, got 0"),
    ("sarcos", ["--seed", "-1", "--sarcos", "x.mat"], "--seed: expected an integer >= 0, got -1"),
    ("fit", ["--data", "x.csv", "--model", "np-inward", "--max-samples", "1"],
     "--max-samples: expected an integer >= 2, got 1"),
    ("fit", ["--data", "x.csv", "--model", "np-inward", "--seed", "-1"], "--seed: expected an integer >= 0, got -1"),
    ("fit", ["--data", "x.csv", "--model", "np-inward", "--threads", "0"],
     "--threads: expected an integer >= 1, got 0"),
    ("fit", ["--data", "x.csv", "--model", "np-inward", "--threads", str(10**30)],  # torch's C int overflowed
     f"--threads: expected at most 1024, got {10**30}"),
])
def test_commands_refuse_bad_options_before_any_work(command, argv, message, tmp_path: Path, monkeypatch,
                                                     capsys) -> None:
    from cascgp_experiments.cli import main

    monkeypatch.chdir(tmp_path)
    write_tiny_ias(tmp_path / "x.mat")
    out = tmp_path / "out"
    with pytest.raises(SystemExit) as exc:
        main([command, "--out", str(out), *argv])
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith(f"cascgp {command}: error: {message}"), err
    assert not out.exists()
