"""The study's curve figures (cascgp_experiments.plots.curve_figure), drawn from a small synthetic block."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from cascgp_experiments import plots


def _block(models: list[str], dof: int = 6, grid: tuple[float, ...] = (1.0, 2.0, 5.0)) -> dict[str, Any]:
    rng = np.random.default_rng(0)
    out = {}
    for m in models:
        med = rng.uniform(0.1, 0.5, (len(grid), dof))
        out[m] = {"nrmse_median": med.tolist(), "nrmse_q25": (med - 0.05).tolist(), "nrmse_q75": (med + 0.05).tolist()}
    return {"dof": dof, "grid_s": list(grid), "models": out}


def _titles(block: dict[str, Any], models: list[str], tmp_path: Path, monkeypatch) -> list[str]:
    seen: list[str] = []

    def keep(fig: Any, path: Path) -> Path:
        seen.extend(ax.get_title() for ax in fig.axes if ax.get_visible() and ax.axison)
        plots._plt().close(fig)
        return path

    monkeypatch.setattr(plots, "_finish", keep)
    plots.curve_figure(block, models, "t", tmp_path / "f.png")
    return seen


def test_a_panel_names_the_cascade_that_is_its_standard_model(tmp_path, monkeypatch) -> None:
    # Inward's first joint is the last (joint 6), outward's the first: there the curves coincide by construction.
    models = ["np-inward", "np-outward", "np-standard", "rbd"]
    titles = _titles(_block(models), models, tmp_path, monkeypatch)
    assert titles == ["Joint 1 (outward = standard)", "Joint 2", "Joint 3", "Joint 4", "Joint 5",
                      "Joint 6 (inward = standard)"]


def test_no_note_without_the_standard_model_or_for_a_seven_joint_arm_s_middle(tmp_path, monkeypatch) -> None:
    models = ["sp-inward-df", "sp-outward-df"]  # no standard curve drawn: nothing coincides
    assert _titles(_block(models), models, tmp_path, monkeypatch) == [f"Joint {j}" for j in range(1, 7)]
    models = ["np-inward", "np-standard"]
    titles = _titles(_block(models, dof=7), models, tmp_path, monkeypatch)
    assert titles == [f"Joint {j}" for j in range(1, 7)] + ["Joint 7 (inward = standard)"]
