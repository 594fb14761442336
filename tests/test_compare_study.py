"""Two runs compared (study, task transfer): zero for a run against itself, every kind of change found and named."""

from __future__ import annotations

import copy
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from cascgp_experiments.compare import compare_results, format_comparison


def _results() -> dict:
    rng = np.random.default_rng(0)
    models = {m: {"nrmse_all": rng.uniform(0.1, 0.5, (3, 4, 2)).tolist()} for m in ("np-standard", "np-inward")}
    pooled = {"fam": [{"a": "np-inward", "b": "np-standard", "interval": [1.0, 2.0], "ratio": 0.9, "p_holm": 0.01},
                      {"a": "np-inward", "b": "np-standard", "interval": [4.0, 5.0], "ratio": 1.1, "p_holm": 0.5}]}
    audit = {"n_gps": 12, "tol_nats": 0.1, "within_tol": 0.9, "gap_max": 0.5, "records": [{"gap": [0.0]}]}
    return {"jaco": {"models": models, "table": {"rows": {"np-standard": [[0.2, 0.3]], "np-inward": [[0.1, 0.2]]}},
                     "pooled": pooled, "audit": audit}}


def test_a_run_against_itself_has_no_changes():
    a = _results()
    c = compare_results(a, copy.deepcopy(a))["jaco"]
    assert c["max_abs_nrmse_change"] == 0 and c["n_cells_over_1pct"] == 0 and c["n_cells"] == 2 * 3 * 4 * 2
    assert c["max_abs_table_change"] == 0
    assert c["pooled"]["fam"] == {"n_tests": 2, "max_abs_ratio_change": 0.0, "changed_verdicts": []}
    assert "records" not in c["audit"]["reference"]


def test_changes_are_found_and_named():
    a = _results()
    b = copy.deepcopy(a)
    x = np.array(b["jaco"]["models"]["np-inward"]["nrmse_all"])
    x[1, 2, 0] *= 1.05  # one value 5 % higher
    x[0, 0, 1] *= 1 + 1e-9  # round-off
    b["jaco"]["models"]["np-inward"]["nrmse_all"] = x.tolist()
    b["jaco"]["table"]["rows"]["np-inward"] = [[0.1, 0.203]]
    b["jaco"]["pooled"]["fam"][1].update(ratio=1.2, p_holm=0.01)  # n.s. -> first worse
    c = compare_results(a, b)["jaco"]
    assert c["n_cells_over_1pct"] == 1 and c["rel_change"]["max"] == pytest.approx(0.05)
    assert c["max_abs_nrmse_change"] == pytest.approx(0.05 * np.array(a["jaco"]["models"]["np-inward"]["nrmse_all"])
                                                      [1, 2, 0])
    assert c["max_abs_table_change"] == pytest.approx(0.003)
    assert c["pooled"]["fam"]["changed_verdicts"] == [{"a": "np-inward", "b": "np-standard", "interval": [4.0, 5.0],
                                                       "before": "n.s.", "after": "first worse"}]
    assert "n.s. -> first worse" in format_comparison(compare_results(a, b))


def test_runs_with_different_models_are_refused():
    a = _results()
    b = copy.deepcopy(a)
    del b["jaco"]["models"]["np-inward"]
    with pytest.raises(ValueError, match="different models"):
        compare_results(a, b)


def test_command_prints_and_writes_json(tmp_path):
    a = _results()
    (tmp_path / "a.json").write_text(json.dumps(a))
    r = subprocess.run([sys.executable, "-m", "scripts.compare_study", str(tmp_path / "a.json"),
                        str(tmp_path / "a.json"), "--json", str(tmp_path / "c.json")],
                       cwd=Path(__file__).resolve().parents[1], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert "0 of 48 values changed" in r.stdout
    assert json.loads((tmp_path / "c.json").read_text())["jaco"]["n_cells"] == 48
    bad = subprocess.run([sys.executable, "-m", "scripts.compare_study", str(tmp_path / "missing.json"),
                          str(tmp_path / "a.json")], cwd=Path(__file__).resolve().parents[1], capture_output=True,
                         text=True, timeout=120)
    assert bad.returncode == 2 and "missing.json" in bad.stderr


def _transfer() -> dict:
    att = [{"task": t, "task_attempt": k, "phase": ph, "tracking_rmse": r, "in_jar": j}
           for t, k, ph, r, j in (("front", 0, "train", 0.43, 0.0), ("front", 1, "train", 0.15, 1.0),
                                  ("left", 0, "train", 0.12, 0.6), ("front", 2, "revisit", 0.14, 1.0))]
    return {"config": {}, "controllers": {"rbd": copy.deepcopy(att), "sp-inward": copy.deepcopy(att)}}


def test_transfer_against_itself_is_identical_and_changes_are_counted():
    from cascgp_experiments.compare import compare_transfer, format_transfer_comparison

    a = _transfer()
    same = compare_transfer(a, copy.deepcopy(a))
    assert all(r["identical"] and r["rmse_abs_change"]["max"] == 0 and r["pour_flips"] == [] for r in same.values())
    b = copy.deepcopy(a)
    b["controllers"]["sp-inward"][2].update(tracking_rmse=0.09, in_jar=0.4)  # tracked better, poured less than half
    c = compare_transfer(a, b)
    assert c["rbd"]["identical"] and not c["sp-inward"]["identical"]
    s = c["sp-inward"]
    assert s["rmse_abs_change"]["max"] == pytest.approx(0.03) and s["rmse_ratio"]["min"] == pytest.approx(0.75)
    assert s["in_jar_abs_change_max"] == pytest.approx(0.2)
    assert s["pour_flips"] == [{"task": "left", "task_attempt": 0, "phase": "train", "in_jar": [0.6, 0.4]}]
    assert s["mean_in_jar"] == pytest.approx([0.65, 0.6])
    assert "| sp-inward | 4 | no | 0.000 / 0.030 | 0.75-1.00 | 0.20 | 1 | 0.65 -> 0.60 |" in \
        format_transfer_comparison(c)


def test_transfer_runs_that_differ_in_controllers_or_attempts_are_refused(tmp_path):
    from cascgp_experiments.compare import compare_transfer

    a = _transfer()
    b = copy.deepcopy(a)
    del b["controllers"]["rbd"]
    with pytest.raises(ValueError, match="different controllers"):
        compare_transfer(a, b)
    b = copy.deepcopy(a)
    b["controllers"]["sp-inward"][3]["phase"] = "train"
    with pytest.raises(ValueError, match="sp-inward: the runs' attempts differ"):
        compare_transfer(a, b)
    (tmp_path / "a.json").write_text(json.dumps(a))
    (tmp_path / "b.json").write_text(json.dumps(b))
    (tmp_path / "study.json").write_text(json.dumps(_results()))
    root = Path(__file__).resolve().parents[1]
    for other, says in (("b.json", "attempts differ"), ("study.json", "no 'controllers'")):
        r = subprocess.run([sys.executable, "-m", "scripts.compare_transfer", str(tmp_path / "a.json"),
                            str(tmp_path / other)], cwd=root, capture_output=True, text=True, timeout=120)
        assert r.returncode == 2 and says in r.stderr
    ok = subprocess.run([sys.executable, "-m", "scripts.compare_transfer", str(tmp_path / "a.json"),
                         str(tmp_path / "a.json"), "--json", str(tmp_path / "c.json")], cwd=root,
                        capture_output=True, text=True, timeout=120)
    assert ok.returncode == 0 and "| rbd | 4 | yes |" in ok.stdout
    assert json.loads((tmp_path / "c.json").read_text())["controllers"]["sp-inward"]["identical"]
