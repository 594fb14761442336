"""The worked example of ``docs/own-robot.md`` runs as written.

Every fenced code block of the page whose opening fence has a ``title="..."`` belongs to the example, in page
order: a ``bash`` block is run line by line (``cascgp ...`` with the installed console script, ``python X.py``
with this interpreter), any other block is written to the file its title names. All of it runs in an empty
folder; the test then checks what the page says the example produces.
"""

from __future__ import annotations

import csv
import json
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
PAGE = REPO / "docs" / "own-robot.md"
_FENCE = re.compile(r'^```(\w+)\s+title="([^"]+)"\s*\n(.*?)^```\s*$', re.MULTILINE | re.DOTALL)


def example_blocks(text: str) -> list[tuple[str, str, str]]:
    """``(language, title, code)`` of every titled fenced block, in page order."""
    return [(m[1], m[2], m[3]) for m in _FENCE.finditer(text)]


def command(line: str) -> list[str]:
    """The argv of one line of a bash block: the ``cascgp`` console script or this interpreter."""
    argv = shlex.split(line)
    if argv[0] == "cascgp":
        exe = Path(sys.executable).with_name("cascgp")
        return [str(exe), *argv[1:]] if exe.exists() else [sys.executable, "-m", "cascgp_experiments.cli", *argv[1:]]
    if argv[0] == "python":
        return [sys.executable, *argv[1:]]
    raise AssertionError(f"docs/own-robot.md: the example runs only cascgp and python, got {line!r}")


def test_the_page_has_the_example() -> None:
    blocks = example_blocks(PAGE.read_text())
    titles = [title for _, title, _ in blocks]
    assert titles[:3] == ["arm.urdf", "make_logs.py", "terminal"], titles
    runs = "\n".join(code for lang, _, code in blocks if lang == "bash")
    for step in ("cascgp fit ", "cascgp evaluate ", "cascgp predict "):
        assert step in runs


def test_the_documented_sidecar_loads_with_the_example_urdf(tmp_path: Path) -> None:
    """The page's sidecar (its one ``json`` block) is read as written, next to the worked example's URDF."""
    import warnings

    from cascgp.rbd import load_nominal

    text = PAGE.read_text()
    sidecar = re.findall(r"^```json\s*\n(.*?)^```\s*$", text, re.MULTILINE | re.DOTALL)
    assert len(sidecar) == 1, "docs/own-robot.md: expected one json block (the sidecar)"
    urdf = dict((title, code) for _, title, code in example_blocks(text))["arm.urdf"]
    (tmp_path / "arm.urdf").write_text(urdf)
    (tmp_path / "arm.json").write_text(sidecar[0])
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a sidecar: no "assuming zero armature" warning
        rbd = load_nominal(tmp_path / "arm.urdf")
    doc = json.loads(sidecar[0])
    assert list(rbd.joint_names) == doc["joint_names"]
    np.testing.assert_array_equal(rbd.armature, doc["armature"])
    np.testing.assert_array_equal(rbd.torque_limits, doc["torque_limits"])
    assert rbd.velocity_limits is None
    np.testing.assert_array_equal(rbd.gravity, doc["gravity"])


def test_worked_example_runs(tmp_path: Path) -> None:
    env = {**os.environ, "OMP_NUM_THREADS": "1", "PYTHONPATH": str(REPO)}
    outputs: list[str] = []
    for lang, title, code in example_blocks(PAGE.read_text()):
        if lang != "bash":
            (tmp_path / title).write_text(code)
            continue
        for line in code.splitlines():
            if not line.strip() or line.lstrip().startswith("#"):
                continue
            r = subprocess.run(command(line), cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
            assert r.returncode == 0, f"{line}\n{r.stdout}\n{r.stderr}"
            outputs.append(r.stdout)

    # what the page says: the stages of the fit, a better model than the URDF alone on every joint, predictions
    scores = json.loads((tmp_path / "scores.json").read_text())
    model, nominal = np.array(scores["nrmse"]["model"]), np.array(scores["nrmse"]["nominal"])
    assert model.shape == nominal.shape == (3,)
    assert np.all(model < nominal), (model, nominal)
    assert model.mean() < 0.5 * nominal.mean(), (model, nominal)
    assert scores["data"]["n_scored"] == 600
    rows = list(csv.reader((tmp_path / "predictions.csv").open()))
    assert rows[0] == ["t", "tau1", "tau2", "tau3", "var1", "var2", "var3"] and len(rows) == 101
    assert "model:" in outputs[-2] and "nominal:" in outputs[-2]
    # the control loop: the learned feedforward tracks better than the URDF alone on every joint
    learned, urdf = (np.array(line.split(":")[1].strip(" []").split(), dtype=float)
                     for line in outputs[-1].splitlines() if line.startswith("tracking error"))
    assert np.all(learned < urdf) and learned.max() < 0.05, (learned, urdf)
