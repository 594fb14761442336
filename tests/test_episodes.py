"""Episode runner and data buffer, on a tiny environment with known dynamics (fast, no MuJoCo)."""

from __future__ import annotations

import numpy as np
import gymnasium as gym
import pytest

from cascgp.buffer import DataBuffer
from cascgp.controller import FeedforwardController
from cascgp.data import DynamicsData
from cascgp.episodes import run_episode

INERTIA = np.array([2.0, 0.5])
DAMPING = np.array([0.3, 0.1])


class SineTask:
    name = "sine"

    def reference(self, t):
        t = np.asarray(t, dtype=float)
        q = 0.3 * np.sin(np.multiply.outer(t, [1.0, 2.0]))
        qd = 0.3 * np.cos(np.multiply.outer(t, [1.0, 2.0])) * [1.0, 2.0]
        qdd = -0.3 * np.sin(np.multiply.outer(t, [1.0, 2.0])) * [1.0, 4.0]
        return q, qd, qdd


class TwoJointEnv(gym.Env):
    """tau = I qdd + b qd, integrated with 1 ms steps; observation [q, qd, tau_applied, t]."""

    observation_space = gym.spaces.Box(-np.inf, np.inf, (7,), np.float64)
    action_space = gym.spaces.Box(-10.0, 10.0, (2,), np.float32)

    def __init__(self, steps: int = 80, dt: float = 0.025):
        self.steps, self.control_dt, self.task = steps, dt, SineTask()

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        q0, qd0, _ = self.task.reference(0.0)  # start on the reference: no initial transient
        self.q, self.qd, self.t, self.k, self.tau = q0.copy(), qd0.copy(), 0.0, 0, np.zeros(2)
        return self._obs(), {}

    def _obs(self):
        return np.concatenate([self.q, self.qd, self.tau, [self.t]])

    def step(self, action):
        self.tau = np.clip(np.asarray(action, dtype=float), -10, 10)
        for _ in range(25):
            qdd = (self.tau - DAMPING * self.qd) / INERTIA
            self.qd = self.qd + 0.001 * qdd
            self.q = self.q + 0.001 * self.qd
        self.t += self.control_dt
        self.k += 1
        err = np.linalg.norm(self.task.reference(self.t)[0] - self.q)
        return self._obs(), -err, self.k >= self.steps, False, {"tracking_error": err}


class ExactID:
    dof = 2

    def inverse_dynamics(self, q, qd, qdd):
        return INERTIA * qdd + DAMPING * qd


def test_episode_records_measurements_with_aligned_torques():
    env = TwoJointEnv()
    ctrl = FeedforwardController(None, 20.0, 5.0, np.full(2, 10.0))
    res = run_episode(env, ctrl, seed=0)
    d = res.data
    assert isinstance(d, DynamicsData) and d.n_samples == env.steps == res.steps
    np.testing.assert_allclose(np.diff(d.t), env.control_dt)
    # The torque recorded at tick k is the one the controller commanded from the state at tick k.
    for k in (0, 10, 40):
        expected = ctrl(d.t[k], d.q[k], d.qd[k], env.task.reference)
        np.testing.assert_allclose(d.tau[k], np.float32(expected), rtol=1e-6)
    # Accelerations are central differences of the measured velocities.
    k = 30
    np.testing.assert_allclose(d.qdd[k], (d.qd[k + 1] - d.qd[k - 1]) / (2 * env.control_dt), rtol=1e-9)
    err = env.task.reference(d.t)[0] - d.q
    np.testing.assert_allclose(res.joint_rmse, np.sqrt(np.mean(err**2, axis=0)))
    assert np.isnan(res.in_jar) and res.n_fallbacks == 0 and not res.unstable


class FaultyEnv(TwoJointEnv):
    """A sensor fault: the velocity reads NaN at the ticks in ``bad``; the reference takes scalar times only."""

    def __init__(self, bad=(), **kw):
        super().__init__(**kw)
        self.bad, self.n_resets = set(bad), 0
        self.task = type("ScalarTask", (), {"name": "sine", "reference": lambda _, t: SineTask().reference(float(t))})()

    def reset(self, **kw):
        self.n_resets += 1
        return super().reset(**kw)

    def _obs(self):
        obs = super()._obs()
        if self.k in self.bad:
            obs[2] = np.nan
        return obs


def test_a_faulty_measurement_is_left_out_of_the_record():
    """The episode runs through a NaN reading (the controller copes); the record leaves its tick out and starts a
    new segment after it; the errors are those of the other ticks, with a reference that takes scalars only."""
    env = FaultyEnv(bad=(20, 21, 50))
    res = run_episode(env, FeedforwardController(None, 20.0, 5.0, np.full(2, 10.0)), seed=0, smoothing=5)
    clean = run_episode(FaultyEnv(), FeedforwardController(None, 20.0, 5.0, np.full(2, 10.0)), seed=0, smoothing=5)
    keep = np.setdiff1d(np.arange(env.steps), [20, 21, 50])
    d = res.data
    assert res.steps == env.steps and d.n_samples == keep.size and d.meta["n_dropped_ticks"] == 3
    assert len(d.segments) == 3 and np.all(np.isfinite(d.qdd))
    np.testing.assert_array_equal(d.t, clean.data.t[keep])
    err = np.array([SineTask().reference(t)[0] for t in d.t]) - d.q
    np.testing.assert_allclose(res.joint_rmse, np.sqrt(np.mean(err**2, axis=0)))


def test_good_ticks_between_faults_too_few_to_differentiate_are_left_out_too():
    ctrl = FeedforwardController(None, 20.0, 5.0, np.full(2, 10.0))
    res = run_episode(FaultyEnv(bad=(20, 23)), ctrl, seed=0)  # ticks 21 and 22 alone: no qdd from two rows
    assert res.data.meta["n_dropped_ticks"] == 4 and len(res.data.segments) == 2
    with pytest.raises(ValueError, match="run_episode: no 3 consecutive ticks of the 80 had finite measurements"):
        run_episode(FaultyEnv(bad=range(0, 80, 2)), ctrl, seed=0)


class _Nameless:
    """A controller without ``name``."""

    dof = 2

    def start(self, env, info) -> None:
        pass

    def __call__(self, t, q, qd, reference):
        return np.zeros(2)


@pytest.mark.parametrize("kwargs, exc, match", [({"smoothing": 4}, ValueError, "SavGol.window"),
                                                ({"smoothing": "5"}, TypeError, "smoothing: expected"),
                                                ({"meta": [1]}, TypeError, "meta: expected a dict"),
                                                ({"meta": {"x": object()}}, TypeError, "meta: expected a JSON"),
                                                ({"callback": 3}, TypeError, "callback: expected a callable"),
                                                ({"controller": None}, TypeError, "controller: expected a controller"),
                                                # no name: the episode ran, then its record failed
                                                ({"controller": _Nameless()}, TypeError,
                                                 r"controller: expected a controller \(dof, name, .*_Nameless"),
                                                ({"controller": FeedforwardController(None, 1.0, 1.0, np.ones(3))},
                                                 ValueError, r"controller: 3 joints, but the env's actions have "
                                                             r"shape \(2,\)")])
def test_bad_arguments_are_refused_before_the_reset(kwargs, exc, match):
    env = FaultyEnv()
    controller = kwargs.pop("controller", FeedforwardController(None, 20.0, 5.0, np.full(2, 10.0)))
    with pytest.raises(exc, match=match):
        run_episode(env, controller, seed=0, **kwargs)
    assert env.n_resets == 0
    with pytest.raises(TypeError, match="env: expected a Gymnasium environment, got NoneType"):
        run_episode(None, controller, seed=0)


def test_exact_feedforward_tracks_better_than_pd():
    # Soft gains: PD alone lags; the exact feedforward leaves only the zero-order-hold error.
    pd = run_episode(TwoJointEnv(), FeedforwardController(None, 4.0, 1.0, np.full(2, 10.0)), seed=0)
    ff = run_episode(TwoJointEnv(), FeedforwardController(ExactID(), 4.0, 1.0, np.full(2, 10.0)), seed=0)
    assert ff.tracking_rmse < 0.3 * pd.tracking_rmse


def test_buffer_persists_and_reloads(tmp_path):
    env = TwoJointEnv()
    ctrl = FeedforwardController(None, 20.0, 5.0, np.full(2, 10.0))
    buf = DataBuffer(tmp_path / "buf")
    for seed in range(3):
        buf.append(run_episode(env, ctrl, seed=seed).data)
    (tmp_path / "buf" / "episode_00003.npz.tmp").write_bytes(b"half-written")  # ignored
    again = DataBuffer(tmp_path / "buf")
    assert len(again) == 3 and again.n_samples == buf.n_samples
    np.testing.assert_array_equal(again.all_data().tau, buf.all_data().tau)
    assert len(np.unique(again.all_data().segment)) == 3


def test_training_set_rate_and_cap(tmp_path):
    env = TwoJointEnv(steps=200)
    buf = DataBuffer()
    for seed in range(2):
        buf.append(run_episode(env, FeedforwardController(None, 20.0, 5.0, np.full(2, 10.0)), seed=seed).data)
    ts = buf.training_set(rate_hz=10.0, max_samples=10_000)
    assert ts.n_samples == 2 * 50  # 5 s at 10 Hz per episode
    capped = buf.training_set(rate_hz=10.0, max_samples=30)
    assert capped.n_samples == 30
    assert set(np.unique(capped.segment)) == set(np.unique(ts.segment))  # every episode keeps its share


def test_buffer_errors():
    buf = DataBuffer()
    with pytest.raises(ValueError, match="empty"):
        buf.training_set()
    with pytest.raises(TypeError, match="DynamicsData"):
        buf.append({"q": 1})
    buf.append(run_episode(TwoJointEnv(), FeedforwardController(None, 1.0, 1.0, np.ones(2)), seed=0).data)
    three = DynamicsData(q=np.zeros((3, 3)), qd=np.zeros((3, 3)), qdd=np.zeros((3, 3)), tau=np.zeros((3, 3)),
                         t=np.arange(3.0))
    with pytest.raises(ValueError, match="dof"):
        buf.append(three)
    for kwargs, match in (({"rate_hz": None}, "rate_hz: expected a finite number > 0"),
                          ({"rate_hz": "10"}, "rate_hz"), ({"max_samples": 10.0}, "max_samples: expected an integer"),
                          ({"max_samples": 1}, "max_samples: expected an integer >= 2")):
        with pytest.raises(ValueError, match=match):
            buf.training_set(**kwargs)
    with pytest.raises(ValueError, match="folder: expected a folder path"):
        DataBuffer("")


def test_a_folder_with_another_robots_episode_is_refused_naming_the_file(tmp_path):
    buf = DataBuffer(tmp_path)
    buf.append(run_episode(TwoJointEnv(), FeedforwardController(None, 1.0, 1.0, np.ones(2)), seed=0).data)
    three = DynamicsData(q=np.zeros((3, 3)), qd=np.zeros((3, 3)), qdd=np.zeros((3, 3)), tau=np.zeros((3, 3)),
                         t=np.arange(3.0))
    three.save(tmp_path / "episode_00001.npz")  # written beside the buffer, not through it
    with pytest.raises(ValueError, match=r"episode_00001.npz holds 3-DOF data, episode_00000.npz 2-DOF data"):
        DataBuffer(tmp_path)


def test_online_controller_learns_inside_the_episode_from_the_runner_measurements():
    """The runner hands every measurement to observe(); an online controller adds every 4th tick's sample
    (q, qd, central-difference qdd, the torque measured over that tick) to its model, and the model's
    prediction at the reference moves toward the true inverse dynamics."""
    from cascgp.gp import GPFitConfig
    from cascgp.models import make_model

    env = TwoJointEnv(steps=200)
    pd = FeedforwardController(None, 20.0, 5.0, np.full(2, 10.0))
    wrong = run_episode(env, pd, seed=0).data  # PD-only data of a *different* motion amplitude
    wrong = DynamicsData(q=0.2 * wrong.q, qd=0.2 * wrong.qd, qdd=0.2 * wrong.qdd, tau=0.2 * wrong.tau, t=wrong.t)
    model = make_model("np-inward", 2, gp_config=GPFitConfig(n_restarts=1, max_iter=50)).fit(wrong.subsample(10))
    q, qd, qdd = SineTask().reference(3.0)
    before = np.abs(model.predict_one(q, qd, qdd) - ExactID().inverse_dynamics(q, qd, qdd)).max()
    ctrl = FeedforwardController(model, 20.0, 5.0, np.full(2, 10.0), online=60)
    res = run_episode(env, ctrl, seed=0)
    assert ctrl.name == "np-inward-online"
    assert abs(ctrl.n_online_samples - res.steps / 4) <= 1
    assert model.n_online == ctrl.n_online_samples and ctrl.n_online_rejected == 0
    after = np.abs(model.predict_one(q, qd, qdd) - ExactID().inverse_dynamics(q, qd, qdd)).max()
    assert after < 0.5 * before
    ctrl.start(env, {})  # a new episode opens a fresh window
    assert model.n_online == 0
