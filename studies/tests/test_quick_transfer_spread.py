"""The quick-transfer spread study's ratios and seed parsing (its runs are the test fixture's own)."""

from __future__ import annotations

import pytest

from studies.commands.quick_transfer_spread import LEARNER, _seeds, main, ratios


def _att(task: str, k: int, rmse: float) -> dict:
    return {"task": task, "task_attempt": k, "tracking_rmse": rmse, "in_jar": 0.0}


def test_the_four_ratios_are_those_the_quick_test_asserts():
    attempts = {"pd": [_att("front", 0, 0.6), _att("left", 0, 0.5)],
                "rbd": [_att("front", 0, 0.45), _att("left", 0, 0.4)],
                LEARNER: [_att("front", 0, 0.45), _att("front", 1, 0.18), _att("left", 0, 0.1)]}
    r = ratios(attempts)
    assert r == pytest.approx({"rbd_over_pd_front": 0.75, "rbd_over_pd_left": 0.8,
                               "learner_front_1_over_rbd": 0.4, "learner_left_0_over_rbd": 0.25})
    del attempts[LEARNER][1]
    with pytest.raises(ValueError, match="expected one attempt 1 on 'front', got 0"):
        ratios(attempts)


def test_seed_lists_and_ranges_parse_and_nonsense_is_refused(tmp_path, capsys):
    assert _seeds("0-3") == [0, 1, 2, 3] and _seeds("2,5-6") == [2, 5, 6] and _seeds("7") == [7]
    with pytest.raises(SystemExit):
        main(["--out", str(tmp_path), "--seeds", "a-b"])
    assert "--seeds: expected integers" in capsys.readouterr().err


def test_sensor_pipeline_option_is_checked_and_defaults_to_the_first_population(tmp_path, capsys):
    import inspect

    from studies.commands.quick_transfer_spread import run_seed

    assert inspect.signature(run_seed).parameters["sensor_pipeline"].default == "ideal"
    with pytest.raises(SystemExit):
        main(["--out", str(tmp_path), "--seeds", "0", "--sensor-pipeline", "real"])
    assert "--sensor-pipeline" in capsys.readouterr().err
