"""One control period of physics, the torque sampling and the instability checks (the env step's hot path).

:class:`ControlPeriod` is what :meth:`jaco_env.envs.base.JacoMujocoEnv._simulate` runs each step:
the command, ``frame_skip`` physics steps, the evaluation of the model at the end state for the
joint torque sensors, and the checks that mark the simulation unstable. It is written for the
cost of a step (profiled with cProfile and MuJoCo's timers, ``python -m scripts.bench_env``):

* **One evaluation per period, shared.** The torque sensors sample at the same instant as q and
  qd (the end of the period) with the command of the period just ended still in effect, so the
  model is evaluated there (``mj_forward``; ``mj_step`` leaves the sensors of the *start* of its
  last physics step). The position and velocity stages of that evaluation are exactly what the
  next period's first physics step computes first: ``mj_step`` is ``mj_step1`` (``mj_checkPos``,
  ``mj_checkVel``, the position and velocity stages) then ``mj_step2`` (actuation, acceleration,
  constraint, ``mj_checkAcc``, integration). So when the state is still the one evaluated (qpos,
  qvel and act bit for bit) and passes those two checks (nothing NaN or beyond ``mjMAXVAL``), that
  step runs ``mj_step2`` alone, with the same result as ``mj_step``. A state changed between steps
  is seen and gets a full ``mj_step``; a change of the *model* between steps needs
  ``mujoco.mj_forward`` afterwards (MuJoCo's rule for ``mj_step2``).
* **No per-step allocation or lookup that can be done once**: views of the data arrays and of the
  warning counters (``data.warning.number`` is live) are fetched at construction, index arrays
  become slices where they are regular; the usual case of the instability checks is screened by
  sums of squares (three or four dot products) before any entry-by-entry check.

The results are those of the plain sequence ``mj_step(nstep=frame_skip)``, ``mj_forward`` and the
checks on the arrays, bit for bit (``tests/test_env_stepping.py``).
"""

from __future__ import annotations

import mujoco
import numpy as np

#: A joint speed (rad/s) or marble speed (m/s) above these marks the simulation unstable.
MAX_JOINT_SPEED = 50.0
MAX_MARBLE_SPEED = 20.0
#: MuJoCo's bound on |qpos|, |qvel| (``mjMAXVAL``): ``mj_checkPos`` / ``mj_checkVel`` reset the data beyond it.
MJ_MAXVAL = 1e10
_max = np.maximum.reduce  # ndarray.max without its Python wrapper (the same reduction)
_dot = np.vdot  # sum of squares of a (n, 3) block (flattened)
# Screens (sums of squares) with a margin: below them no entry can exceed the bound, whatever the rounding.
_SCREEN_MAXVAL2 = 0.99 * MJ_MAXVAL**2
_SCREEN_JOINT2 = 0.99 * MAX_JOINT_SPEED**2
_SCREEN_MARBLE2 = 0.99 * MAX_MARBLE_SPEED**2


def as_index(adr: np.ndarray) -> slice | np.ndarray:
    """``adr`` as a slice where it is an ascending arithmetic run (a view, not a gather), else itself."""
    adr = np.asarray(adr)
    if len(adr) == 0:
        return adr
    step = int(adr[1] - adr[0]) if len(adr) > 1 else 1
    if step > 0 and np.array_equal(adr, adr[0] + step * np.arange(len(adr))):
        return slice(int(adr[0]), int(adr[-1]) + 1, step)
    return adr


def live_view(arr: np.ndarray, adr: np.ndarray) -> np.ndarray:
    """``arr[adr]`` as a view that follows ``arr`` (nothing to gather per read); ``adr`` must be an ascending
    arithmetic run (``ValueError`` otherwise), as the arm's addresses are (the arm is the scene's first tree)."""
    idx = as_index(adr)
    if not isinstance(idx, slice):
        raise ValueError(f"addresses {np.asarray(adr).tolist()} are not an ascending arithmetic run")
    return arr[idx]


class ControlPeriod:
    """Advance one ``MjData`` by control periods of ``frame_skip`` physics steps (see the module docstring).

    ``ctrl_slots``: the ``data.ctrl`` slices that receive the action (torque mode: the motors; velocity
    mode: also the reference integrators). ``tau_adr``: the ``sensordata`` entries of the joint torques,
    ``arm_dof_adr`` the arm's dofs (speed check); :meth:`watch_marbles` adds the marbles' speed check.
    """

    def __init__(self, model: mujoco.MjModel, data: mujoco.MjData, frame_skip: int, ctrl_slots: list[slice],
                 tau_adr: np.ndarray, arm_dof_adr: np.ndarray):
        self.model, self.data, self.frame_skip = model, data, int(frame_skip)
        self._ctrl, self._ctrl_slots = data.ctrl, list(ctrl_slots)
        self._sensordata, self._tau = data.sensordata, as_index(tau_adr)
        self._warn = data.warning.number  # a live view of the warning counters
        self._qpos, self._qvel, self._act = data.qpos, data.qvel, data.act
        self._qd_arm = live_view(data.qvel, arm_dof_adr)
        self._arm_is_all = self._qd_arm.size == model.nv  # its speed screen then bounds all of qvel
        self._marble_lin: np.ndarray | None = None
        self.tau = np.zeros(len(np.asarray(tau_adr)))
        self.forget()

    def watch_marbles(self, marble_dof_adr: np.ndarray) -> None:
        """Also check the linear speed of the free joints at ``marble_dof_adr`` (their first dof each)."""
        adr = np.asarray(marble_dof_adr, dtype=int)
        self._marble_lin = adr[:, None] + np.arange(3) if len(adr) else None

    def forget(self) -> None:
        """After a reset: no evaluated state to reuse, warning counts from zero."""
        self._evaluated: tuple[bytes, bytes, bytes] | None = None  # qpos, qvel, act last evaluated
        self._warn_counts = np.zeros(len(self._warn), dtype=np.int64)
        self._warn_seen: bytes | None = None  # the counters' bytes when last compared with _warn_counts

    def run(self, a: np.ndarray) -> bool:
        """Apply ``a``, advance one period, sample the torques into :attr:`tau`; True when unstable."""
        m, d, qpos, qvel, act = self.model, self.data, self._qpos, self._qvel, self._act
        for s in self._ctrl_slots:
            self._ctrl[s] = a
        n = self.frame_skip
        ev = self._evaluated
        first2 = (ev is not None and qpos.tobytes() == ev[0] and qvel.tobytes() == ev[1]
                  and act.tobytes() == ev[2])
        if first2:
            mujoco.mj_step2(m, d)
            n -= 1
        if n:
            mujoco.mj_step(m, d, nstep=n)
        mujoco.mj_forward(m, d)
        self.tau = self._sensordata[self._tau].copy()

        # A new MuJoCo warning, a NaN/inf in qpos or qvel, or a too fast joint or marble: unstable. Sums of
        # squares screen the usual case (nothing NaN, above mjMAXVAL or near a speed limit: a square above
        # the bound would show, with a margin far beyond round-off); else the entries are checked one by one.
        w = self._warn
        wb = w.tobytes()
        new_warning = False
        if wb != self._warn_seen:
            new_warning = bool((w > self._warn_counts).any())
            self._warn_counts, self._warn_seen = w.copy(), wb
        qd_arm = self._qd_arm
        lin = None if self._marble_lin is None else qvel[self._marble_lin]
        if (qd_arm.dot(qd_arm) < _SCREEN_JOINT2 and qpos.dot(qpos) < _SCREEN_MAXVAL2
                and (self._arm_is_all or qvel.dot(qvel) < _SCREEN_MAXVAL2)
                and (lin is None or _dot(lin, lin) < _SCREEN_MARBLE2)):
            unstable, stage = new_warning, True
        else:
            big = max(_max(np.abs(qpos)), _max(np.abs(qvel)))  # NaN if any entry is NaN
            unstable = new_warning or not big < np.inf
            if not unstable:
                unstable = bool(_max(np.abs(qd_arm)) > MAX_JOINT_SPEED)
            if not unstable and lin is not None:
                unstable = bool(_max(np.sqrt(np.add.reduce(lin * lin, axis=1))) > MAX_MARBLE_SPEED)  # norm(axis=1)
            stage = bool(big <= MJ_MAXVAL)  # mj_checkPos / mj_checkVel would pass
        # the evaluation can begin the next period while the state stays this one
        self._evaluated = (qpos.tobytes(), qvel.tobytes(), act.tobytes()) if stage else None
        return unstable
