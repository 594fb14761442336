"""What the nominal rigid-body model misses on the simulated Jaco 2: a per-joint breakdown.

:func:`breakdown` runs one noise-free sum-of-sinusoids motion (``JacoPayload-v0``, velocity mode, the idealised
``sensor_pipeline="ideal"``,
100 Hz, the data-efficiency study's protocol), computes the residual ``tau - tau_RBD(q, qd, qdd)`` of
the nominal model (``jaco_env/assets/jaco2_nominal.urdf``) with qdd from the study's Savitzky-Golay filter, and
again with the true accelerations (the env's privileged ``info["qacc"]``). The measured torque is
link-side, so it holds no rotor inertia or joint friction: what remains with the true qdd is the
payload and the calibration error; the difference between the two is the acceleration estimate's
share. The command line is ``python -m scripts.residual_breakdown``.
"""

from __future__ import annotations

import os

import numpy as np

os.environ.setdefault("MUJOCO_GL", "egl")

import gymnasium as gym

import jaco_env
from cascgp.data import DynamicsData, SavGol
from cascgp.rbd import load_nominal
from jaco_env.excitation import make_command

#: Rows of the printed table: (key of :func:`breakdown`'s result, label).
ROWS = (("tau_std", "std of measured torque"), ("residual_mean", "mean of RBD residual"),
        ("residual_std", "std of RBD residual"), ("residual_true_qdd_std", "std of RBD residual with the true qdd"))


def breakdown(seconds: float, seed: int, rate_hz: float = 100.0) -> dict[str, list[float]]:
    """Per joint (N m): spread of the measured torque, mean and spread of the RBD residual (estimated and true qdd)."""
    # The idealised signal (no read skew, offset or filter): the residual is then the model's alone.
    env = gym.make("JacoPayload-v0", control_mode="velocity", control_freq=rate_hz, sensor_noise=None,
                   sensor_pipeline="ideal")
    urdf = jaco_env.nominal_urdf(env.unwrapped.link_inertials)
    obs, _ = env.reset(seed=seed)
    command = make_command(seed, seconds)
    rows, qacc = [], []
    for k in range(int(seconds * rate_hz)):
        obs, _, _, _, info = env.step(np.asarray(command(k / rate_hz), dtype=np.float32))
        rows.append(jaco_env.split_obs(obs))
        qacc.append(info["qacc"])
    env.close()
    t, q, qd, tau = (np.array([r[i] for r in rows]) for i in (3, 0, 1, 2))
    qacc = np.array(qacc)
    data = DynamicsData.from_measurements(t, q, qd, tau,
                                          smoothing=SavGol(9, 2))
    rbd = load_nominal(urdf)
    residual = data.tau - rbd.inverse_dynamics(data.q, data.qd, data.qdd)
    residual_true = data.tau - rbd.inverse_dynamics(data.q, data.qd, qacc)
    return {
        "tau_std": data.tau.std(0).tolist(),
        "residual_mean": residual.mean(0).tolist(),
        "residual_std": residual.std(0).tolist(),
        "residual_true_qdd_std": residual_true.std(0).tolist(),
    }
