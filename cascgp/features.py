"""State features and the standard / inward / outward input maps (paper section III).

State of joint j (0-based here, 1-based in the paper):

* derivative based (``kind="db"``): ``s_j = (q_j, qd_j, qdd_j)``;
* derivative free (``kind="df"``): ``s_j = (q_j(t), q_j(t - delta), q_j(t - 2 delta))``, i.e.
  the paper's reduced-rank feature ``xi_j = R q_j(t^-)`` with ``k = 3``, ``M = 2`` and
  ``R = I``.  The history comes from the same segment by linear interpolation in time.

Inputs of the GP of joint i (1-based, N joints):

==========  ============================================  ===========================
structure   inputs                                         dimension
==========  ============================================  ===========================
standard    s_1 ... s_N                                    3N
inward      tau_{i+1}, s_1 ... s_i   (joint N: s_1..s_N)    3i + 1   (3N for joint N)
outward     tau_{i-1}, s_i ... s_N   (joint 1: s_1..s_N)    3(N-i+1) + 1 (3N for joint 1)
==========  ============================================  ===========================

The paper prints ``3(N-i)+1`` for the outward case, but the vector it writes,
``[tau_{i-1}, q_i..q_N, qd_i..qd_N, qdd_i..qdd_N]``, has N-i+1 joints, hence
``3(N-i+1)+1``; we implement the vector.

In the arrays built here the state columns come first, joint by joint
(``q_j, qd_j, qdd_j`` for each joint in order; the order of columns does not matter to an ARD
kernel), and the neighbour torque is the LAST column when present.
"""

from __future__ import annotations

import numpy as np

from .checks import check_positive
from .data import DynamicsData

__all__ = ["STRUCTURES", "FEATURE_KINDS", "state_features", "states_from_arrays", "input_spec",
           "input_dim", "build_inputs", "history_from_data"]

STRUCTURES = ("standard", "inward", "outward")
FEATURE_KINDS = ("db", "df")


def _check_kind(kind: str) -> None:
    if kind not in FEATURE_KINDS:
        raise ValueError(f"kind: expected one of {FEATURE_KINDS}, got {kind!r}")


def _check_delta(delta: float) -> float:
    return check_positive(delta, "delta", "s")


def history_from_data(data: DynamicsData, delta: float) -> tuple[np.ndarray, np.ndarray]:
    """``q(t - delta)`` and ``q(t - 2 delta)`` for every row of ``data``.

    Returns ``(q_hist (T, 2, N), valid (T,))``: linear interpolation in time within the row's
    segment; where ``t - 2 delta`` lies before the segment's first sample the value is clamped
    to that first sample (finite, but ``valid`` is False there).
    """
    delta = _check_delta(delta)
    T, N = data.q.shape
    q_hist = np.empty((T, 2, N))
    valid = np.zeros(T, dtype=bool)
    for lo, hi in data.segment_bounds():
        ts, qs = data.t[lo:hi], data.q[lo:hi]
        tol = 1e-9 * max(1.0, float(np.max(np.abs(ts))))
        for m in (1, 2):
            tq = ts - m * delta
            for j in range(N):
                q_hist[lo:hi, m - 1, j] = np.interp(tq, ts, qs[:, j])
        valid[lo:hi] = ts - 2 * delta >= ts[0] - tol
    return q_hist, valid


def states_from_arrays(kind: str, q: np.ndarray, qd: np.ndarray | None = None,
                       qdd: np.ndarray | None = None, q_hist: np.ndarray | None = None) -> np.ndarray:
    """Per-joint states ``S (T, N, 3)`` from query arrays (no validation beyond shapes).

    db: ``S[:, j] = (q_j, qd_j, qdd_j)``; df: ``S[:, j] = (q_j, q_hist[:, 0, j], q_hist[:, 1, j])``.
    """
    _check_kind(kind)
    if kind == "db":
        if qd is None or qdd is None:
            raise ValueError("states_from_arrays: kind 'db' needs qd and qdd")
        return np.stack([q, qd, qdd], axis=-1)
    if q_hist is None:
        raise ValueError("states_from_arrays: kind 'df' needs q_hist")
    return np.stack([q, q_hist[:, 0, :], q_hist[:, 1, :]], axis=-1)


def state_features(data: DynamicsData, kind: str = "db", delta: float = 0.1
                   ) -> tuple[np.ndarray, np.ndarray]:
    """State features of every row: ``(S (T, N, 3), valid (T,) bool)``.

    ``kind="db"``: ``(q, qd, qdd)`` per joint, all rows valid.  ``kind="df"``:
    ``(q(t), q(t - delta), q(t - 2 delta))`` per joint from the same segment (linear
    interpolation); rows whose history reaches before the segment's start are marked invalid
    (their S is finite: history clamped to the first sample of the segment).
    """
    _check_kind(kind)
    if not isinstance(data, DynamicsData):
        raise TypeError(f"data: expected DynamicsData, got {type(data).__name__}")
    if kind == "db":
        return states_from_arrays("db", data.q, data.qd, data.qdd), np.ones(data.n_samples, bool)
    q_hist, valid = history_from_data(data, delta)
    return states_from_arrays("df", data.q, q_hist=q_hist), valid


def input_spec(structure: str, joint: int, dof: int) -> tuple[tuple[int, ...], int | None]:
    """``(state_joints, torque_joint)`` of the GP of ``joint`` (0-based) in an arm of ``dof``
    joints; ``torque_joint`` is None when the GP has no torque input (see the module table)."""
    if structure not in STRUCTURES:
        raise ValueError(f"structure: expected one of {STRUCTURES}, got {structure!r}")
    if not isinstance(dof, (int, np.integer)) or dof < 1:
        raise ValueError(f"dof: expected a positive integer, got {dof!r}")
    if not isinstance(joint, (int, np.integer)) or not 0 <= joint < dof:
        raise ValueError(f"joint: expected an integer in [0, {dof - 1}], got {joint!r}")
    joint, dof = int(joint), int(dof)
    if structure == "standard":
        return tuple(range(dof)), None
    if structure == "inward":  # tau_{i+1}, s_1..s_i ; last joint: all states, no torque
        if joint == dof - 1:
            return tuple(range(dof)), None
        return tuple(range(joint + 1)), joint + 1
    # outward: tau_{i-1}, s_i..s_N ; first joint: all states, no torque.
    # (paper prints 3(N-i)+1; its vector has N-i+1 joints -> 3(N-i+1)+1)
    if joint == 0:
        return tuple(range(dof)), None
    return tuple(range(joint, dof)), joint - 1


def input_dim(structure: str, joint: int, dof: int) -> int:
    """Input dimension of the GP of ``joint`` (0-based): ``3 * len(state_joints) + (torque?)``."""
    sj, tj = input_spec(structure, joint, dof)
    return 3 * len(sj) + (tj is not None)


def build_inputs(S: np.ndarray, tau: np.ndarray | None, structure: str) -> list[np.ndarray]:
    """GP inputs of every joint: ``X_j = [S[:, state_joints].reshape(T, -1), tau[:, torque_joint]]``
    (torque column last when present).  ``tau`` (T, N) may be None for ``"standard"``."""
    S = np.asarray(S, dtype=np.float64)
    if S.ndim != 3 or S.shape[2] != 3:
        raise ValueError(f"S: expected shape (T, N, 3), got {S.shape}")
    T, N, _ = S.shape
    if tau is not None:
        tau = np.asarray(tau, dtype=np.float64)
        if tau.shape != (T, N):
            raise ValueError(f"tau: expected shape {(T, N)}, got {tau.shape}")
    out = []
    for j in range(N):
        sj, tj = input_spec(structure, j, N)
        cols = [S[:, list(sj), :].reshape(T, -1)]
        if tj is not None:
            if tau is None:
                raise ValueError(f"tau: required for structure {structure!r} (joint {j} takes tau_{tj})")
            cols.append(tau[:, tj:tj + 1])
        out.append(np.ascontiguousarray(np.concatenate(cols, axis=1)))
    return out

