"""What the model commands (``cascgp fit``, ``evaluate``, ``predict``) note about a log on stderr: its rate, rows
outside the URDF's limits or far outside the training positions, in-sample rows, too few rows. A note points at a
likely mistake without stopping the command."""

from __future__ import annotations

import sys
from typing import Any

import numpy as np

__all__ = ["note", "periods", "log_rate", "limits_note", "coverage_note", "in_sample_note", "few_rows_note"]


def note(prog: str, msg: str) -> None:
    """``msg`` on stderr as ``<prog>: <msg>``."""
    print(f"{prog}: {msg}", file=sys.stderr, flush=True)


def periods(data: Any) -> np.ndarray:
    """The sample periods within the log's segments (s)."""
    return np.diff(data.t)[np.diff(data.segment) == 0]


def log_rate(data: Any) -> str:
    """The log's sample rate from its median period within segments, as text."""
    steps = periods(data)
    return f"about {1.0 / np.median(steps):.4g} Hz" if steps.size and np.median(steps) > 0 else "unknown"


def limits_note(prog: str, rbd: Any, data: Any) -> str | None:
    """One note naming the joints with rows outside the URDF's position limits by more than a tenth of their span
    (positions in degrees, or another zero, say); joints without limits (continuous) are not checked. Returns it
    (``None``: no note, or a rigid-body model without URDF limits)."""
    if not hasattr(rbd, "position_limits"):  # None (an NP model), or an inverse-dynamics object without URDF limits
        return None
    m = rbd.pin_model
    checks = [(f"q{j + 1}", data.q[:, j], lo, hi) for j, (lo, hi) in enumerate(rbd.position_limits)]
    for name, (joint, mult, offset) in rbd.coupled.items():  # a mimic joint moved by its joint: its own limits too
        i = m.idx_qs[m.getJointId(name)]
        checks.append((f"{name} (moving with {joint})", mult * data.q[:, rbd.joint_names.index(joint)] + offset,
                       m.lowerPositionLimit[i], m.upperPositionLimit[i]))
    found = []
    for label, x, lo, hi in checks:
        if np.isfinite(lo) and np.isfinite(hi) and hi > lo:
            pad = 0.1 * (hi - lo)
            out = float(((x < lo - pad) | (x > hi + pad)).mean())
            if out > 0:
                found.append(f"{label} {out:.0%} ([{lo:.4g}, {hi:.4g}])")
    if found:
        msg = (f"rows outside the URDF's position limits: {', '.join(found)}; positions must be in rad (m for a "
               "prismatic joint), 0 at the URDF's zero")
        note(prog, f"note: {msg}")
        return msg
    return None


def torque_note(prog: str, rbd: Any, data: Any) -> str | None:
    """One note naming the joints with rows whose torque exceeds twice the URDF's (or its sidecar's) limit (N mm or
    another unit, say; a motor's short peak stays within twice its rating); returns it (``None``: no note, no
    torques, or a rigid-body model without torque limits)."""
    limits = getattr(rbd, "torque_limits", None)
    if limits is None or data.meta.get("has_tau") is False:
        return None
    found = []
    for j, lim in enumerate(limits):
        size = np.abs(data.tau[:, j])
        out = float((size > 2.0 * lim).mean())
        if out > 0:
            share = f"{out:.0%}" if out >= 0.01 else "<1%"
            found.append(f"tau{j + 1} {share} (limit {lim:.4g}, largest {size.max():.4g})")
    if not found:
        return None
    msg = (f"rows with torques beyond twice the URDF's effort limits (or the sidecar's torque_limits): "
           f"{', '.join(found)}; torques must be in N m (N for a prismatic joint)")
    note(prog, f"note: {msg}")
    return msg


def coverage_note(prog: str, model: Any, data: Any) -> str | None:
    """One note naming the joints with at least 5 % of the rows far outside the positions the model was trained on:
    more than the training range's width beyond it (ordinary extrapolation near the range is not noted); returns
    it (``None``: no note)."""
    from cascgp.models.coverage import fraction_outside, training_position_range

    out = fraction_outside(model, data.q, margin=1.0)
    far = np.flatnonzero(out >= 0.05)
    if far.size:
        r = training_position_range(model)
        found = [f"q{j + 1} {out[j]:.0%} ([{r[j, 0]:.4g}, {r[j, 1]:.4g}])" for j in far]
        fades = ("it gives the rigid-body torque plus the training data's mean residual" if model.rbd is not None
                 else "it gives each joint's mean torque of the training log")
        msg = (f"rows far outside the positions the model was trained on (more than the range's width beyond it): "
               f"{', '.join(found)}; the model knows nothing there ({fades}). A log in another unit, or in another "
               "range of turns of a continuous joint, than the training log?")
        note(prog, f"note: {msg}")
        return msg
    return None


def in_sample_note(prog: str, model: Any, data: Any) -> str | None:
    """A note when at least 5 % of a test log's rows are the model's training rows (their positions bit for bit), or
    when the log holds at least half of the model's training rows (a model fitted on a few of a long log's rows,
    evaluated on that log); returns it (``None``: no note)."""
    from cascgp.models.coverage import training_overlap

    share, held = training_overlap(model, data.q)
    if share >= 0.05 or held >= 0.5:
        rows = round(share * data.n_samples)
        msg = (f"{rows} of the log's {data.n_samples} rows ({share:.1%}) are the model's training rows (the same "
               f"positions, bit for bit; {held:.0%} of its training rows are in the log): scores on them are "
               "in-sample, not a test; evaluate on a log the model was not fitted to")
        note(prog, f"note: {msg}")
        return msg
    return None


def few_rows_note(prog: str, model: Any, data: Any, thinned: bool) -> None:
    """A note before a fit on fewer rows than a GP has inputs (``thinned``: by --max-samples)."""
    inputs = max(3 * len(sj) + (tj is not None) for sj, tj in model.specs)
    if data.n_samples < inputs:
        more = "raise --max-samples" if thinned else "log more, and more varied, motion"
        note(prog, f"note: {data.n_samples} rows for GPs of up to {inputs} inputs: too few to learn from, the model "
                    f"stays close to its {'rigid-body model' if model.rbd is not None else 'prior'}; {more}")
