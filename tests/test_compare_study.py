"""Comparison of two study runs: zero for a run against itself, every kind of change found and named."""

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
