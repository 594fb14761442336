"""The fit-accuracy experiment's decision rules (scripts.fit_accuracy) and its command-line checks, on made-up
arms (no fit, no GPyTorch)."""

from __future__ import annotations

import pytest

from scripts.bench_cascgp import main
from scripts.fit_accuracy import FIT_ACCURACY_SETS, fit_accuracy_verdict

ARMS = ("A0", "A-gls", "A-floor", "G0", "G0-in-cascgp", "G-zero", "G-floor", "G-init", "G0-polish")


def _arms(a0: float, floor: float) -> dict:
    """Arms of one data set: every arm at ``a0`` on 6 outputs, A-floor at ``floor``, G0 better than A0."""
    out = {}
    for a in ARMS:
        e = {"A-floor": floor, "G0": 0.9 * a0}.get(a, a0)
        out[a] = {"test_nrmse_median": e, "test_nrmse": [e] * 6, "nll_zero_mean": [0.0] * 6}
    return out


def test_a_candidate_better_on_every_set_is_adopted_only_from_a_run_of_all_three() -> None:
    names = [s[0] for s in FIT_ACCURACY_SETS]
    every = {k: _arms(0.1, 0.098) for k in names}  # A-floor 2 % better on every output of every set
    assert fit_accuracy_verdict(every)["candidates"]["A-floor"]["adopt"]
    one = {names[2]: _arms(0.1, 0.098)}
    assert not fit_accuracy_verdict(one)["candidates"]["A-floor"]["adopt"]
    small = {k: _arms(0.1, 0.0995) for k in names}  # 0.5 %: below the rule's 1 %
    assert not fit_accuracy_verdict(small)["candidates"]["A-floor"]["adopt"]


def test_a_run_of_some_arms_applies_only_the_rules_of_those_arms() -> None:
    name = FIT_ACCURACY_SETS[1][0]
    arms = {a: v for a, v in _arms(0.1, 0.098).items() if a in ("A0", "A-gls", "G0", "G0-in-cascgp", "G-init",
                                                               "G0-polish")}
    v = fit_accuracy_verdict({name: arms})
    r = v["per_set"][name]
    assert set(r["fraction_closed"]) == {"G-init", "G0-in-cascgp", "G0-polish"} and set(r["explains"]) == {"G-init"}
    assert r["explains"]["G-init"] and r["H2_holds"]  # both back at A0's error: the whole gap closed
    assert v["candidates"]["A-floor"] == {"adopt": False, "not_run_on": [name]}


@pytest.mark.parametrize("argv, message", [
    (["--fit-arms", "G1"], "--fit-arms: unknown arm(s) ['G1']"),
    (["--fit-sets", "D4"], "--fit-sets: expected some of D1,D2,D3"),
    (["--fit-sets", ""], "--fit-sets: expected some of D1,D2,D3"),
    (["--fit-sets", "D1,D3"], "needs --sarcos for D1 and D2"),
])
def test_fit_sets_are_checked_before_anything_runs(tmp_path, capsys, argv, message) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["--out", str(tmp_path / "out"), "--fit-accuracy", *argv])
    assert exc.value.code == 2 and message in capsys.readouterr().err
    assert not (tmp_path / "out").exists()
