"""The sensing factorial study (studies.sensing_factorial): the effect against a closed form on a synthetic block,
the two primary families' sizes and Holm correction, and the command (--quick on two arms; all seven arms in the
slow set)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from studies.sensing_factorial import ARMS, effect, verdicts

S, N = 10, 6
GRID = [1.0, 1.5, 2.0, 4.0, 4.5, 5.0, 9.0, 9.5, 10.0]


def _block(a: float, b: float, seed: int = 0, spread: float = 0.0) -> dict:
    """Synthetic curves: per parametrisation, the inward cascade is the standard model times exp(a) on joints 1-5,
    the outward one times exp(b) on joints 2-6; the chain-first joints carry a huge factor that must be left out.
    ``spread`` adds per-subset noise to the log ratios."""
    rng = np.random.default_rng(seed)
    models = {}
    for p in ("np", "sp"):
        std = rng.uniform(0.05, 0.5, (S, len(GRID), N))
        inward, outward = std.copy(), std.copy()
        inward[:, :, :5] *= np.exp(a + spread * rng.standard_normal((S, 1, 1)))
        inward[:, :, 5] *= np.exp(100.0)
        outward[:, :, 1:] *= np.exp(b + spread * rng.standard_normal((S, 1, 1)))
        outward[:, :, 0] *= np.exp(100.0)
        models[f"{p}-standard"] = {"nrmse_all": std}
        models[f"{p}-inward"] = {"nrmse_all": inward, "measured": {"nrmse_all": inward * 2.0}}
        models[f"{p}-outward"] = {"nrmse_all": outward, "measured": {"nrmse_all": outward * 2.0}}
    return {"grid_s": GRID, "models": models}


def test_effect_is_the_mean_log_ratio_over_the_joints_that_differ() -> None:
    block = _block(-0.2, 0.1)
    for lo, hi in ((1, 2), (4, 5), (9, 10)):
        np.testing.assert_allclose(effect(block, "np", lo, hi), np.full(S, (-0.2 + 0.1) / 2), atol=1e-12)
    np.testing.assert_allclose(effect(block, "sp", 1, 2, cascades=("inward",)), -0.2, atol=1e-12)
    np.testing.assert_allclose(effect(block, "sp", 1, 2, "measured"), (-0.2 + 0.1) / 2 + np.log(2.0), atol=1e-12)
    # the log ratio is averaged over the grid points, not the nRMSE: a ratio that varies with T
    block["models"]["np-inward"]["nrmse_all"][:, :3, :5] *= np.array([1.0, np.e, np.e**2])[None, :, None]
    np.testing.assert_allclose(effect(block, "np", 1, 2, cascades=("inward",)), -0.2 + 1.0, atol=1e-12)
    with pytest.raises(ValueError, match="no grid point"):
        effect(block, "np", 20, 30)


def test_primary_families_have_their_sizes_and_holm_correction() -> None:
    blocks = {arm: _block(0.0, 0.0, seed=k, spread=0.05) for k, arm in enumerate(ARMS)}
    blocks["+torque"] = _block(-0.3, -0.3, seed=99, spread=0.01)  # cascades clearly better in every subset
    v = verdicts(blocks)
    changes, wins = v["factor_changes_effect"], v["cascades_beat_standard"]
    assert len(changes) == 12 and len(wins) == 14
    assert {t["arm"] for t in changes} == set(ARMS) - {"ideal"}
    for fam in (changes, wins):
        p = np.array([t["p"] for t in fam])
        adj = np.array([t["p_holm"] for t in fam])
        assert np.all(adj >= p - 1e-15) and np.all(adj <= 1.0)
        assert np.isclose(adj.min(), min(1.0, len(fam) * p.min()))
    torque = [t for t in wins if t["arm"] == "+torque"]
    assert all(t["verdict"] == "cascades win" and t["p"] == pytest.approx(2 / 2**S) for t in torque)
    assert all(t["verdict"] == "matters: cascades helped" for t in changes if t["arm"] == "+torque")
    assert all(t["verdict"] == "no detected difference" for t in wins if t["arm"] == "ideal")
    unadjusted = verdicts(blocks, (4.0, 5.0), adjust=False)
    assert all("verdict" not in t and "p_holm" not in t for t in unadjusted["factor_changes_effect"])


def _run_quick(tmp_path, arms: str) -> dict:
    from studies.commands.sensing_factorial import main

    assert main(["--out", str(tmp_path), "--quick", "--arms", arms, "--workers", "1"]) == 0
    res = json.loads((tmp_path / "factorial.json").read_text())
    assert (tmp_path / "factorial.png").stat().st_size > 0 and "verdicts" not in res
    for arm in arms.split(","):
        for p in ("np", "sp"):
            for key in ("1-2", "4-5", "9-10"):
                rec = res["effects"][f"{arm}|{p}|{key}"]
                assert rec["predicted"]["n"] == 2 and np.isfinite(rec["predicted"]["ratio"])
    return res


def test_quick_command_on_two_arms(tmp_path) -> None:
    res = _run_quick(tmp_path, "ideal,jaco2")
    ideal, jaco2 = res["arms"]["ideal"], res["arms"]["jaco2"]
    assert ideal["nominal_urdf"] == "jaco2_nominal.urdf" and jaco2["nominal_urdf"] == "jaco2_nominal_kinova.urdf"
    assert jaco2["collection"]["sensor_pipeline"] == "jaco2" and res["meta"]["protocol_commit"]
    md = (tmp_path / "factorial.md").read_text()
    assert "| jaco2 | SP |" in md and "(--quick: no verdicts)" in md
    # the report renders again from the JSON alone
    from studies.commands.sensing_factorial import main

    (tmp_path / "factorial.md").unlink()
    assert main(["--report", str(tmp_path / "factorial.json"), "--slim", str(tmp_path / "slim.json")]) == 0
    assert (tmp_path / "factorial.md").read_text() == md
    # the documentation's copy keeps every per-subset score and renders the same report
    from studies.sensing_factorial_report import markdown

    slim = json.loads((tmp_path / "slim.json").read_text())
    assert markdown(slim) == md
    assert slim["arms"]["jaco2"]["curves"]["models"]["sp-inward"]["nrmse_all"] == \
        res["arms"]["jaco2"]["curves"]["models"]["sp-inward"]["nrmse_all"]


def test_bad_arms_are_refused(tmp_path, capsys) -> None:
    from studies.commands.sensing_factorial import main

    with pytest.raises(SystemExit):
        main(["--out", str(tmp_path), "--arms", "ideal,+friction"])
    assert "--arms: expected names of" in capsys.readouterr().err


@pytest.mark.slow
def test_quick_command_on_every_arm(tmp_path) -> None:
    res = _run_quick(tmp_path, ",".join(ARMS))
    assert list(res["arms"]) == list(ARMS)
