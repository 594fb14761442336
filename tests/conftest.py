"""Shared fixtures: an analytic planar arm (known inverse dynamics) and the SARCOS folder."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest
import torch

from cascgp.data import DynamicsData

# One torch thread for the whole suite: on the 2-core CI machine, and whenever other
# processes share the cores, torch's second (spinning) thread made GP fits 10-30x slower
# (n=100, 3 GPs: 0.37 s with 1 thread vs 11.3 s with 2 under load).  Single queries are
# faster on one thread anyway (DESIGN.md).
torch.set_num_threads(1)

REPO = Path(__file__).resolve().parents[1]
SARCOS_DIR = (REPO / ".." / "shared" / "data" / "sarcos").resolve()
G = 9.81


def _cross2(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


@dataclass
class PlanarArm:
    """N-link planar arm in a vertical plane (gravity along -y), revolute joints.

    Link i: length ``l[i]``, mass ``m[i]``, centre of mass at ``c[i]`` along the link,
    inertia ``I[i]`` about the centre of mass.  ``inverse_dynamics`` is a planar recursive
    Newton-Euler written here from the textbook equations (independent of Pinocchio), plus
    optional viscous friction ``friction * qd`` (not part of the "rigid-body" model when
    ``friction`` is zero).  Duck-types the ``RigidBodyModel`` API (``dof``,
    ``inverse_dynamics(q, qd, qdd)`` for (N,) or (T, N)).
    """

    l: np.ndarray
    m: np.ndarray
    c: np.ndarray
    I: np.ndarray
    friction: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def __post_init__(self) -> None:
        self.l, self.m, self.c, self.I = (np.asarray(a, float) for a in (self.l, self.m, self.c, self.I))
        if self.friction.size == 0:
            self.friction = np.zeros(self.dof)

    @property
    def dof(self) -> int:
        return int(self.l.size)

    def inverse_dynamics(self, q, qd, qdd) -> np.ndarray:
        q, qd, qdd = (np.asarray(a, float) for a in (q, qd, qdd))
        single = q.ndim == 1
        if single:
            q, qd, qdd = q[None], qd[None], qdd[None]
        T, N = q.shape
        th = np.cumsum(q, axis=1)
        w = np.cumsum(qd, axis=1)
        al = np.cumsum(qdd, axis=1)
        a_o = np.zeros((T, 2))
        a_o[:, 1] = G  # base accelerating upwards == gravity downwards
        a_c = np.empty((T, N, 2))
        u = np.stack([np.cos(th), np.sin(th)], axis=-1)  # (T, N, 2)
        perp = np.stack([-u[..., 1], u[..., 0]], axis=-1)
        for i in range(N):
            a_c[:, i] = a_o + (al[:, i, None] * perp[:, i] - w[:, i, None] ** 2 * u[:, i]) * self.c[i]
            a_o = a_o + (al[:, i, None] * perp[:, i] - w[:, i, None] ** 2 * u[:, i]) * self.l[i]
        tau = np.empty((T, N))
        f_next = np.zeros((T, 2))
        n_next = np.zeros(T)
        for i in reversed(range(N)):
            f_i = self.m[i] * a_c[:, i] + f_next
            n_i = (self.I[i] * al[:, i] + n_next + _cross2(self.c[i] * u[:, i], self.m[i] * a_c[:, i])
                   + _cross2(self.l[i] * u[:, i], f_next))
            tau[:, i] = n_i
            f_next, n_next = f_i, n_i
        tau = tau + self.friction * qd
        return tau[0] if single else tau


def two_link_closed_form(arm: PlanarArm, q, qd, qdd) -> np.ndarray:
    """Textbook closed-form M(q) qdd + C(q, qd) qd + g(q) of a 2-link planar arm."""
    l1 = arm.l[0]
    m1, m2 = arm.m
    c1, c2 = arm.c
    I1, I2 = arm.I
    q1, q2 = q[:, 0], q[:, 1]
    M11 = I1 + I2 + m1 * c1**2 + m2 * (l1**2 + c2**2 + 2 * l1 * c2 * np.cos(q2))
    M12 = I2 + m2 * (c2**2 + l1 * c2 * np.cos(q2))
    M22 = I2 + m2 * c2**2
    h = m2 * l1 * c2 * np.sin(q2)
    g1 = (m1 * c1 + m2 * l1) * G * np.cos(q1) + m2 * c2 * G * np.cos(q1 + q2)
    g2 = m2 * c2 * G * np.cos(q1 + q2)
    t1 = M11 * qdd[:, 0] + M12 * qdd[:, 1] - h * (2 * qd[:, 0] * qd[:, 1] + qd[:, 1] ** 2) + g1
    t2 = M12 * qdd[:, 0] + M22 * qdd[:, 1] + h * qd[:, 0] ** 2 + g2
    return np.stack([t1, t2], axis=1) + arm.friction * qd


def make_arm(dof: int = 3, friction: float = 0.0) -> PlanarArm:
    l = np.array([0.5, 0.4, 0.3, 0.25, 0.2, 0.15, 0.1][:dof])
    m = np.array([2.0, 1.5, 1.0, 0.8, 0.6, 0.4, 0.3][:dof])
    return PlanarArm(l=l, m=m, c=0.5 * l, I=m * l**2 / 12.0, friction=np.full(dof, friction))


def sinusoid_data(arm: PlanarArm, seconds: float, rate_hz: float, seed: int, *,
                  noise: float = 0.0, n_sines: int = 3) -> DynamicsData:
    """Sum-of-sinusoids joint trajectories with exact qd, qdd and tau = arm.inverse_dynamics
    (+ Gaussian torque noise of std ``noise``)."""
    rng = np.random.default_rng(seed)
    N = arm.dof
    t = np.arange(int(round(seconds * rate_hz))) / rate_hz
    A = rng.uniform(0.2, 0.6, (n_sines, N)) / n_sines * 2
    w = rng.uniform(0.3, 1.5, (n_sines, N)) * 2 * np.pi / 2
    ph = rng.uniform(0, 2 * np.pi, (n_sines, N))
    off = rng.uniform(-0.5, 0.5, N)
    arg = w[None] * t[:, None, None] + ph[None]
    q = off + (A * np.sin(arg)).sum(1)
    qd = (A * w * np.cos(arg)).sum(1)
    qdd = (-A * w**2 * np.sin(arg)).sum(1)
    tau = arm.inverse_dynamics(q, qd, qdd)
    if noise:
        tau = tau + noise * rng.standard_normal(tau.shape)
    return DynamicsData(q=q, qd=qd, qdd=qdd, tau=tau, t=t, meta={"robot": f"planar{N}", "seed": seed})


@pytest.fixture(scope="session")
def arm3() -> PlanarArm:
    """3-link planar arm with viscous friction 0.3 N m s/rad (the 'true' robot)."""
    return make_arm(3, friction=0.3)


@pytest.fixture(scope="session")
def arm3_rbd() -> PlanarArm:
    """The rigid-body part of ``arm3`` (no friction): the RBD model an SP variant gets."""
    return make_arm(3, friction=0.0)


@pytest.fixture(scope="session")
def arm3_train(arm3) -> DynamicsData:
    return sinusoid_data(arm3, 60.0, 10.0, seed=1, noise=0.01)


@pytest.fixture(scope="session")
def arm3_test(arm3) -> DynamicsData:
    return sinusoid_data(arm3, 30.0, 10.0, seed=2)


@pytest.fixture(scope="session")
def sarcos_dir() -> Path:
    """The SARCOS folder (../shared/data/sarcos relative to the repo); skips if missing."""
    if not (SARCOS_DIR / "ias_sarcos_data.mat").exists():
        pytest.skip(f"SARCOS data not found at {SARCOS_DIR}")
    return SARCOS_DIR


def write_tiny_ias(path: Path) -> Path:
    """A file with the IAS SARCOS variables and column counts (3 training and 2 test rows of zeros): what the
    commands check before they run (``cascgp.sarcos.check_ias``), for tests that replace the run itself."""
    from scipy.io import savemat

    savemat(path, {"X_train": np.zeros((3, 21)), "Y_train": np.zeros((3, 7)), "X_test": np.zeros((2, 21)),
                   "Y_test": np.zeros((2, 7))})
    return path


@pytest.fixture(scope="module")
def fitted_planar_model(arm3_train):
    """An NP inward cascade of ``arm3`` on 80 rows (2 starts): the controller tests' fitted model."""
    from cascgp.gp import GPFitConfig
    from cascgp.models import make_model

    data = arm3_train.take(np.arange(min(80, arm3_train.n_samples)))
    return make_model("np-inward", data.dof, gp_config=GPFitConfig(n_restarts=2, max_iter=200)).fit(data)
