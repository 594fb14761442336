"""Soak test: a bounded-duration run of everything a long experiment does, checking for NaN, crashes
and memory growth. The thin CLI is ``scripts/soak.py``.

One **cycle** (repeated until the time budget is spent, at least once):

1. for both ``JacoPour-v0`` (random number of marbles, torque or velocity mode) and ``JacoPayload-v0`` (torque
   or velocity mode), in random order: ``gym.make``, 1-3 episodes with a random task (pour), a random payload
   (``reset`` option, or drawn by the env) and random actions (uniform within the bounds, sometimes far
   outside them: the env clips), then ``close``;
2. each episode's measurements (``jaco_env.split_obs``) become a :class:`~cascgp.data.DynamicsData` appended
   to a :class:`~cascgp.buffer.DataBuffer` on disk; once it holds ``buffer_episodes`` episodes, at the end of
   the cycle, the folder is reopened (all episodes must load back) and replaced by a fresh one, so that the
   data held stay bounded;
3. a retrain: ``make_model(model, 6, gp_config=GPFitConfig(n_restarts=1, max_iter=30))`` fitted on
   ``buffer.training_set(max_samples=200)``, its predictions on the newest episode (``predict`` and
   ``predict_one``), and a save / ``load_model`` round trip that must give the same predictions.

**Fails** (``SoakResult.passed`` False, the CLI exits 1 with the message) on a NaN/inf in an observation, a
reward or a prediction, on any exception, or when the resident memory grows by more than ``rss_bound_mib``
(default :data:`RSS_BOUND_MIB` = 150 MiB) over its level after the warm-up (``warmup_cycles`` cycles, default 2:
MuJoCo's mesh cache, torch's and glibc's pools fill during the first makes and fits). The bound is about
40 times what a flat run shows (a few MiB) and well below what the mesh-cache leak of an earlier version produced
(~4 MiB per ``gym.make``, 2 makes per cycle: over 150 MiB within 20 cycles).

Reported (``SoakResult.to_json``): steps, episodes (and how many ended unstable or terminated), resets, makes,
closes, retrains, samples appended, buffer reopenings, RSS (MiB) at start, after the warm-up, at the end and
peak (sampled after every episode, and the kernel's ``ru_maxrss``), a per-cycle RSS trace, the wall time, the
load average at start and end (the machine may be shared) and versions.

``fault`` injects a failure to check the checks (used by the tests): ``"nan-obs"`` (an observation is replaced
by NaN), ``"nan-prediction"``, ``"exception"`` (raised inside a step) or ``"leak"`` (the cycle keeps 2 x the
bound of memory alive).
"""

from __future__ import annotations

import gc
import os
import platform
import resource
import shutil
import sys
import time
import traceback
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

#: Allowed resident-memory growth after the warm-up (MiB).
RSS_BOUND_MIB = 150.0
FAULTS = ("nan-obs", "nan-prediction", "exception", "leak")


class SoakFailure(RuntimeError):
    """A check of the soak failed (NaN, memory growth); the message says what and where."""


@dataclass
class SoakConfig:
    """Settings of a soak run (the CLI's options).

    Attributes:
        minutes: time budget (min); the run stops starting cycles after it (the last cycle finishes).
        seed: seed of every random choice (tasks, payloads, actions, env seeds).
        rss_bound_mib: allowed RSS growth over the level after the warm-up (MiB).
        warmup_cycles: cycles before the RSS baseline is taken (0: at the start of the first cycle).
        max_steps: longest episode (control steps); each episode runs a random 10 .. max_steps steps.
        max_marbles: ``JacoPour-v0`` gets a random 1 .. max_marbles marbles per make.
        buffer_episodes: episodes per buffer folder before it is reopened and replaced (at the end of a cycle).
        model: the cascgp model retrained every cycle.
        max_samples: training-set size cap (``DataBuffer.training_set``).
        fault: inject a failure (one of :data:`FAULTS`) to test the checks; ``None`` in a real run.
        progress_s: seconds between progress lines (0: none).
    """

    minutes: float
    seed: int = 0
    rss_bound_mib: float = RSS_BOUND_MIB
    warmup_cycles: int = 2
    max_steps: int = 200
    max_marbles: int = 30
    buffer_episodes: int = 24
    model: str = "np-inward"
    max_samples: int = 200
    fault: str | None = None
    progress_s: float = 15.0

    def __post_init__(self) -> None:
        for name in ("minutes", "rss_bound_mib"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v) or v <= 0:
                raise ValueError(f"SoakConfig.{name} must be a finite number > 0, got {v!r}")
        for name, lo in (("warmup_cycles", 0), ("max_steps", 10), ("max_marbles", 1), ("buffer_episodes", 1),
                         ("max_samples", 2)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < lo:
                raise ValueError(f"SoakConfig.{name} must be an integer >= {lo}, got {v!r}")
        if self.fault is not None and self.fault not in FAULTS:
            raise ValueError(f"SoakConfig.fault must be one of {FAULTS} or None, got {self.fault!r}")


@dataclass
class SoakResult:
    """What a soak run did and found (JSON via :meth:`to_json`)."""

    config: dict[str, Any]
    passed: bool = False
    failure: str | None = None
    traceback: str | None = None
    cycles: int = 0
    steps: int = 0
    episodes: int = 0
    episodes_unstable: int = 0
    episodes_terminated: int = 0
    resets: int = 0
    makes: int = 0
    closes: int = 0
    retrains: int = 0
    samples_appended: int = 0
    buffer_reopens: int = 0
    rss_start_mib: float = 0.0
    rss_after_warmup_mib: float | None = None
    rss_end_mib: float = 0.0
    rss_peak_mib: float = 0.0
    rss_peak_kernel_mib: float = 0.0
    rss_growth_after_warmup_mib: float | None = None
    rss_trace: list[dict[str, float]] = field(default_factory=list)
    wall_s: float = 0.0
    loadavg_start: list[float] = field(default_factory=list)
    loadavg_end: list[float] = field(default_factory=list)
    environment: dict[str, Any] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        return asdict(self)

    def summary(self) -> str:
        growth = ("n/a (run shorter than the warm-up)" if self.rss_growth_after_warmup_mib is None
                  else f"{self.rss_growth_after_warmup_mib:+.1f} MiB (bound {self.config['rss_bound_mib']:.0f})")
        lines = [
            f"soak {'PASSED' if self.passed else 'FAILED'} after {self.wall_s / 60:.1f} min, {self.cycles} cycles",
            f"  steps {self.steps}, episodes {self.episodes} ({self.episodes_unstable} unstable, "
            f"{self.episodes_terminated} terminated), resets {self.resets}, makes {self.makes}, "
            f"closes {self.closes}, retrains {self.retrains}, samples appended {self.samples_appended}, "
            f"buffer reopens {self.buffer_reopens}",
            f"  RSS start {self.rss_start_mib:.0f} MiB, after warm-up "
            f"{'n/a' if self.rss_after_warmup_mib is None else f'{self.rss_after_warmup_mib:.0f} MiB'}, "
            f"end {self.rss_end_mib:.0f} MiB, peak {self.rss_peak_mib:.0f} MiB "
            f"(kernel max {self.rss_peak_kernel_mib:.0f} MiB); growth after warm-up {growth}",
        ]
        if self.failure:
            lines.append(f"  FAILURE: {self.failure}")
        return "\n".join(lines)


def rss_mib() -> float:
    """Resident set size of this process (MiB), from ``/proc/self/status`` (Linux); the peak elsewhere."""
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return _peak_rss_mib()


def _peak_rss_mib() -> float:
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return peak / (1024.0 * 1024.0) if sys.platform == "darwin" else peak / 1024.0


def _loadavg() -> list[float]:
    try:
        return [round(x, 2) for x in os.getloadavg()]
    except OSError:
        return []


def _check_finite(what: str, value, where: str) -> None:
    a = np.asarray(value, dtype=float)
    if not np.all(np.isfinite(a)):
        raise SoakFailure(f"non-finite {what} ({where}): {np.asarray(value).ravel()[:8].tolist()}")


class _Soak:
    def __init__(self, cfg: SoakConfig, out: Path, log: Callable[[str], None]):
        import gymnasium as gym
        import torch

        import jaco_env

        torch.set_num_threads(1)  # the machine may be shared; one thread is also the fastest for small fits
        self.gym, self.jaco_env = gym, jaco_env
        self.cfg, self.out, self.log = cfg, out, log
        self.rng = np.random.default_rng(cfg.seed)
        self.res = SoakResult(config=asdict(cfg))
        self.buffer_dir = out / "buffer"
        self.buffer = None
        self._buffer_count = 0
        self._leak: list[np.ndarray] = []
        self._last_episode = None
        self._fault_armed = cfg.fault

    # ------------------------------------------------------------------ pieces
    def _sample_rss(self) -> float:
        r = rss_mib()
        self.res.rss_peak_mib = max(self.res.rss_peak_mib, r)
        return r

    def _new_buffer(self) -> None:
        from cascgp.buffer import DataBuffer

        shutil.rmtree(self.buffer_dir, ignore_errors=True)
        self.buffer = DataBuffer(self.buffer_dir)
        self._buffer_count = 0

    def _rotate_buffer(self) -> None:
        """Reopen the folder (every episode must load back), then start a fresh one."""
        from cascgp.buffer import DataBuffer

        again = DataBuffer(self.buffer_dir)
        if len(again) != len(self.buffer) or again.n_samples != self.buffer.n_samples:
            raise SoakFailure(f"buffer reopened with {len(again)} episodes / {again.n_samples} samples, "
                              f"expected {len(self.buffer)} / {self.buffer.n_samples}")
        self.res.buffer_reopens += 1
        self._new_buffer()

    def _action(self, env) -> np.ndarray:
        lim = env.action_space.high.astype(float)
        kind = self.rng.random()
        if kind < 0.1:  # far outside the bounds: clipped by the env
            return self.rng.uniform(-10.0, 10.0, lim.shape) * lim
        return self.rng.uniform(-1.0, 1.0, lim.shape) * lim * self.rng.choice([0.1, 0.3, 1.0])

    def _episode(self, env, env_id: str) -> None:
        from jaco_env import scene

        u = env.unwrapped
        options: dict[str, Any] = {}
        if env_id == "JacoPour-v0":
            from jaco_env.tasks import DEFAULT_TASKS

            if self.rng.random() < 0.8:
                options["task"] = str(self.rng.choice(sorted(DEFAULT_TASKS)))
            lo = scene.bottle_mass(u.n_marbles) + 0.01
        else:
            lo = 0.2
        if self.rng.random() < 0.7:
            options["payload_mass"] = float(self.rng.uniform(lo, 1.6))
        obs, info = env.reset(seed=int(self.rng.integers(2**31)), options=options or None)
        self.res.resets += 1
        where = f"{env_id} reset, cycle {self.res.cycles}"
        _check_finite("observation", obs, where)
        rows = [obs]
        n_steps = int(self.rng.integers(10, self.cfg.max_steps + 1))
        terminated = truncated = False
        for k in range(n_steps):
            obs, reward, terminated, truncated, info = env.step(self._action(env))
            self.res.steps += 1
            if self._fault_armed == "exception" and self.res.steps >= 5:
                raise RuntimeError("injected exception (fault='exception')")
            if self._fault_armed == "nan-obs" and self.res.steps >= 5:
                obs = np.full_like(obs, np.nan)
            where = f"{env_id} step {k + 1} of episode {self.res.episodes + 1}, cycle {self.res.cycles}"
            _check_finite("observation", obs, where)
            _check_finite("reward", reward, where)
            if truncated and info.get("unstable", False):
                break  # the env returns the last finite observation again: not a new sample
            rows.append(obs)
            if terminated or truncated:
                break
        self.res.episodes += 1
        self.res.episodes_unstable += int(bool(info.get("unstable", False)))
        self.res.episodes_terminated += int(bool(terminated))
        self._append(np.asarray(rows), env_id)

    def _append(self, rows: np.ndarray, env_id: str) -> None:
        from cascgp.data import DynamicsData

        if len(rows) < 5:
            return
        q, qd, tau, t = self.jaco_env.split_obs(rows)
        data = DynamicsData.from_measurements(t, q, qd, tau, meta={"env": env_id, "soak_cycle": self.res.cycles})
        self.buffer.append(data)
        self._last_episode = data
        self.res.samples_appended += data.n_samples
        self._buffer_count += 1

    def _env_round(self, env_id: str) -> None:
        kwargs: dict[str, Any] = {"control_mode": str(self.rng.choice(["torque", "velocity"]))}
        if env_id == "JacoPour-v0":
            kwargs["n_marbles"] = int(self.rng.integers(1, self.cfg.max_marbles + 1))
        env = self.gym.make(env_id, **kwargs)
        self.res.makes += 1
        try:
            for _ in range(int(self.rng.integers(1, 4))):
                self._episode(env, env_id)
        finally:
            env.close()
            self.res.closes += 1

    def _retrain(self) -> None:
        from cascgp.gp import GPFitConfig
        from cascgp.models import load_model, make_model

        if self.buffer is None or len(self.buffer) == 0 or self._last_episode is None:
            return
        train = self.buffer.training_set(max_samples=self.cfg.max_samples)
        if train.n_samples < 5:
            return
        cfg = GPFitConfig(n_restarts=1, max_iter=30, seed=int(self.rng.integers(2**31)))
        model = make_model(self.cfg.model, self.jaco_env.robot.N_JOINTS, gp_config=cfg).fit(train)
        self.res.retrains += 1
        test = self._last_episode
        mean, var = model.predict_data(test)
        one = model.predict_one(test.q[0], test.qd[0], test.qdd[0])
        if self._fault_armed == "nan-prediction":
            mean = mean.copy()
            mean[0, 0] = np.nan
        where = f"retrain {self.res.retrains}, cycle {self.res.cycles}"
        _check_finite("prediction mean", mean, where)
        _check_finite("prediction variance", var, where)
        _check_finite("predict_one", one, where)
        path = model.save(self.out / "model.npz")
        again = load_model(path)
        if not np.allclose(again.predict_data(test)[0], mean, rtol=1e-9, atol=1e-9):
            raise SoakFailure(f"the saved model predicts differently after load_model ({where})")

    def _check_memory(self, rss: float) -> None:
        base = self.res.rss_after_warmup_mib
        if base is not None and rss - base > self.cfg.rss_bound_mib:
            raise SoakFailure(f"resident memory grew by {rss - base:.0f} MiB after the warm-up ({base:.0f} -> "
                              f"{rss:.0f} MiB), more than the bound of {self.cfg.rss_bound_mib:.0f} MiB "
                              f"(cycle {self.res.cycles})")

    # ------------------------------------------------------------------ the run
    def run(self) -> SoakResult:
        res, cfg = self.res, self.cfg
        res.loadavg_start = _loadavg()
        res.environment = _environment()
        t0 = time.monotonic()
        deadline = t0 + 60.0 * cfg.minutes
        next_progress = t0 + cfg.progress_s
        res.rss_start_mib = self._sample_rss()
        try:
            self.out.mkdir(parents=True, exist_ok=True)
            self._new_buffer()
            while True:
                if res.cycles == cfg.warmup_cycles:
                    gc.collect()
                    res.rss_after_warmup_mib = self._sample_rss()
                if cfg.fault == "leak":
                    self._leak.append(np.ones(int(2 * cfg.rss_bound_mib * 2**20 / 8) + 1))
                for env_id in self.rng.permutation(["JacoPour-v0", "JacoPayload-v0"]):
                    self._env_round(str(env_id))
                self._retrain()
                if self._buffer_count >= cfg.buffer_episodes:  # after the retrain: every retrain has data
                    self._rotate_buffer()
                res.cycles += 1
                gc.collect()
                rss = self._sample_rss()
                res.rss_trace.append({"cycle": res.cycles, "elapsed_s": round(time.monotonic() - t0, 1),
                                      "rss_mib": round(rss, 1)})
                self._check_memory(rss)
                now = time.monotonic()
                if cfg.progress_s and now >= next_progress:
                    next_progress = now + cfg.progress_s
                    self.log(f"[soak {(now - t0) / 60:5.1f}/{cfg.minutes:g} min] cycles {res.cycles}, steps "
                             f"{res.steps}, episodes {res.episodes}, makes {res.makes}, retrains {res.retrains}, "
                             f"RSS {rss:.0f} MiB (peak {res.rss_peak_mib:.0f})")
                if now >= deadline:
                    break
            res.passed = True
        except Exception as exc:  # noqa: BLE001 - any exception is a soak failure, reported with its traceback
            res.failure = str(exc) if isinstance(exc, SoakFailure) else f"{type(exc).__name__}: {exc}"
            res.traceback = traceback.format_exc()
        finally:
            self._leak.clear()
            res.wall_s = round(time.monotonic() - t0, 1)
            gc.collect()
            res.rss_end_mib = rss_mib()
            res.rss_peak_kernel_mib = _peak_rss_mib()
            if res.rss_after_warmup_mib is not None:
                res.rss_growth_after_warmup_mib = round(res.rss_end_mib - res.rss_after_warmup_mib, 1)
            res.loadavg_end = _loadavg()
            shutil.rmtree(self.buffer_dir, ignore_errors=True)
        for name in ("rss_start_mib", "rss_end_mib", "rss_peak_mib", "rss_peak_kernel_mib"):
            setattr(res, name, round(getattr(res, name), 1))
        if res.rss_after_warmup_mib is not None:
            res.rss_after_warmup_mib = round(res.rss_after_warmup_mib, 1)
        return res


def _environment() -> dict[str, Any]:
    import gymnasium
    import mujoco
    import torch

    return {"python": platform.python_version(), "platform": platform.platform(), "cpus": os.cpu_count(),
            "mujoco": mujoco.__version__, "gymnasium": gymnasium.__version__, "torch": torch.__version__,
            "numpy": np.__version__}


def run_soak(cfg: SoakConfig, out: str | os.PathLike, log: Callable[[str], None] = print) -> SoakResult:
    """Run the soak (module docstring) with its scratch files under ``out``; write ``out/soak.json``."""
    out = Path(out)
    result = _Soak(cfg, out, log).run()
    out.mkdir(parents=True, exist_ok=True)
    from cascgp.io import write_json

    write_json(out / "soak.json", result.to_json())
    (out / "model.npz").unlink(missing_ok=True)
    return result

