"""Collect the simulated Jaco data set of the data-efficiency study (the paper's protocol).

Protocol (paper section IV-B-1, simulated):

* ``JacoPayload-v0`` in ``control_mode="velocity"``: the action is a joint velocity command that the
  emulated Kinova firmware loop turns into torques; the robot carries a fixed rigid payload
  (``payload_mass``, default 0.8 kg) that the nominal URDF does not contain.
* Each motion commands every joint rate as a sum of sinusoids with random amplitudes, frequencies
  and phases (``jaco_env.excitation``), seeded per motion.
* Training: ``n_subsets`` (10) motions of ``subset_seconds`` (60) s each, i.e. 600 s in 10 subsets,
  each with its own random parameters (one segment per subset). Test: ``n_test`` (3) motions of
  ``test_seconds`` (60) s with new random parameters (other seeds).
* Start-up: every motion starts at rest while its command starts at ``v(0) != 0``; the first
  ``warmup_seconds`` (2 s) of each motion, the firmware loop's start-up transient, are simulated
  but not recorded, for every model alike.
* Recorded at ``rate_hz`` (default 100 Hz = the env's control rate here): only the *measured*
  observation ``[q, qd, tau, t]`` (with the env's default sensor noise; tau is the link-side joint
  torque) is kept; ``qdd`` comes from the measured ``qd`` through a Savitzky-Golay differentiating
  filter (window ``savgol_window`` = 9 samples = 90 ms, polynomial order 2; centred, no phase
  lag; :meth:`DynamicsData.from_measurements`). Its error against the true accelerations (read from
  the env's privileged ``info["qacc"]`` and never stored as data) and the true acceleration spread
  are reported in ``meta["qdd_error"]``. Measured on a 20 s motion (seed 7): true q̈ spread
  0.7-1.4 rad/s² per joint; filter RMSE 0.19-0.44 rad/s²; noise-free central differences are
  already 0.17-0.41 off, because the zero-order-hold velocity command steps every 10 ms and the
  firmware loop answers each step at once, so the instantaneous q̈ of a sample differs from any
  average over neighbouring samples (windows 5-31 and orders 2-5 were within 10 % of each other;
  9 / 2 was the lowest with noise). The study subsamples to 10 Hz afterwards.

Files: ``<out>/jaco_train.npz`` and ``<out>/jaco_test.npz`` (:meth:`DynamicsData.save`), reused when
present with the same settings (``meta["collection"]``).

Parallel: every motion is one job of :mod:`cascgp_experiments.execution` (``workers`` local processes,
or a Ray cluster); ``vector_env=True`` runs the motions of a split side by side in a Gymnasium
``AsyncVectorEnv`` instead. Every motion is seeded on its own, so the files are the same whatever the
worker count or the backend (tested). Jobs are the default because an env step here is cheap, so the vector
env's lockstep (one round trip to every sub-process per step) costs more than it gains (measured side by side:
``docs/parallel.md``, ``python -m scripts.bench_parallel --cases collect-full``).

Ablations (``docs/studies/calibration.md``, not the study's data): ``sensor_noise="none"`` records noiseless
measurements (the motions are the same: the command is open loop and the firmware acts on the simulator's state);
``qdd_source="true"`` stores the simulator's true accelerations instead of the filtered ones.
The default ``sensor_pipeline="jaco2"`` reads the joint state through the real arm's sensing pipeline
(``jaco_env.signal_pipeline``), differentiates q̇ with the causal filter (``qdd_filter``, factor (d)) and simulates
the arm with Kinova's URDF link inertials (``link_inertials``, factor (e)); ``sensor_pipeline="ideal"`` gives the
idealised signal (synchronous samples, true velocity, no torque offset or filter), the centred filter and
dm_control's inertials.

Command line: ``cascgp collect --out out/study/data [--quick|--smoke] [--workers N] [--ray ADDRESS]
[--sensor-noise none] [--qdd true] [--sensor-pipeline ideal] [--qdd-filter causal] [--link-inertials kinova]``.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Callable

import numpy as np
from tqdm import tqdm

from cascgp.checks import check_count, check_positive
from cascgp.data import DynamicsData, SavGol
from cascgp.io import write_json
from cascgp_experiments.common import machine_info, package_versions

ENV_ID = "JacoPayload-v0"


@dataclass(frozen=True)
class CollectConfig:
    """Settings of one collection (all of it goes into ``meta["collection"]``)."""

    n_subsets: int = 10
    subset_seconds: float = 60.0
    n_test: int = 3
    test_seconds: float = 60.0
    rate_hz: float = 100.0
    payload_mass: float = 0.8
    seed: int = 0
    warmup_seconds: float = 2.0
    savgol_window: int = 9
    savgol_polyorder: int = 2
    #: ``"default"``: the env's ``SensorNoise()``; ``"none"``: noiseless measurements (``SensorNoise.none()``),
    #: the ablation of ``docs/studies/calibration.md``. The motions do not depend on it (open-loop command, the
    #: firmware loop acts on the simulator's state); the random stream is the same (noise is always drawn).
    sensor_noise: str = "default"
    #: ``"savgol"``: q̈ from the measured q̇ by the Savitzky-Golay filter (the study's); ``"true"``: the
    #: simulator's true accelerations ``info["qacc"]`` (privileged; for the calibration ablation only).
    qdd_source: str = "savgol"
    #: The env's ``sensor_pipeline`` (``jaco_env.signal_pipeline``): ``"jaco2"`` (the default: the real arm's
    #: read skew, differentiated velocity, torque offset, drift, filter and noise per actuator; values and
    #: sources in ``docs/sensing-sources.md``), ``"ideal"`` (the idealised signal) or ``"ideal+<factor>[+...]"``
    #: (factors ``skew``, ``velocity``, ``torque`` of ``jaco_env.signal_pipeline.FACTORS`` on top of ``ideal``).
    sensor_pipeline: str = "jaco2"
    #: The q̈ filter (factor (d) of the sensing pipeline): ``"centred"`` (the Savitzky-Golay fit evaluated at its
    #: centre: zero phase, offline) or ``"causal"`` (evaluated at the newest sample, as a controller running
    #: online computes it: ``cascgp.derivatives.SavGol(causal=True)``); ``None`` follows ``sensor_pipeline``
    #: (``"jaco2"``: causal, ``"ideal"``: centred).
    qdd_filter: str | None = None
    #: The arm's link inertials (the env option ``link_inertials``, factor (e)): ``"dm_control"`` or ``"kinova"``
    #: (``jaco_env.link_inertials``); ``None`` follows ``sensor_pipeline`` (``"jaco2"``: Kinova's, otherwise
    #: dm_control's). The nominal URDF of a model fitted to these data should be ``jaco_env.nominal_urdf`` of the
    #: same value (:attr:`nominal_link_inertials`).
    link_inertials: str | None = None

    @property
    def nominal_link_inertials(self) -> str:
        """The link inertials the data's arm has (:attr:`link_inertials` resolved)."""
        from jaco_env.link_inertials import resolve

        return resolve(self.link_inertials, self.sensor_pipeline)

    @property
    def smoothing(self) -> SavGol:
        """The q̈ filter this collection uses (see :attr:`qdd_filter`)."""
        causal = (self.qdd_filter or ("causal" if self.sensor_pipeline == "jaco2" else "centred")) == "causal"
        return SavGol(self.savgol_window, self.savgol_polyorder, causal=causal)

    def __post_init__(self) -> None:
        def store(name: str, value: object) -> None:  # as Python numbers: the settings go into JSON and job keys
            object.__setattr__(self, name, value)

        for name, least in (("n_subsets", 1), ("n_test", 1), ("seed", 0)):  # seed: Gymnasium takes seeds >= 0
            store(name, check_count(getattr(self, name), name, least))
        for name in ("subset_seconds", "test_seconds", "rate_hz", "warmup_seconds"):
            store(name, check_positive(getattr(self, name), name, "Hz" if name == "rate_hz" else "s",
                                       zero=name == "warmup_seconds"))
        if (not isinstance(self.savgol_window, int) or self.savgol_window < 3 or self.savgol_window % 2 == 0
                or not isinstance(self.savgol_polyorder, int) or not 1 <= self.savgol_polyorder < self.savgol_window):
            raise ValueError(f"savgol_window/savgol_polyorder: expected an odd window >= 3 and 1 <= polyorder < "
                             f"window, got {self.savgol_window!r}/{self.savgol_polyorder!r}")
        from jaco_env.scene import check_rigid_payload_mass

        store("payload_mass", check_rigid_payload_mass(self.payload_mass, "payload_mass"))  # its env: JacoPayload-v0
        if self.sensor_noise not in SENSOR_NOISE:
            raise ValueError(f"sensor_noise: expected one of {SENSOR_NOISE}, got {self.sensor_noise!r}")
        if self.qdd_source not in QDD_SOURCES:
            raise ValueError(f"qdd_source: expected one of {QDD_SOURCES}, got {self.qdd_source!r}")
        check_pipeline(self.sensor_pipeline)
        if self.qdd_filter is not None and self.qdd_filter not in QDD_FILTERS:
            raise ValueError(f"qdd_filter: expected None or one of {QDD_FILTERS}, got {self.qdd_filter!r}")
        if self.link_inertials is not None:
            from jaco_env.link_inertials import LINK_INERTIALS

            if self.link_inertials not in LINK_INERTIALS:
                raise ValueError(f"link_inertials: expected None or one of {LINK_INERTIALS}, "
                                 f"got {self.link_inertials!r}")


#: Values of :attr:`CollectConfig.sensor_noise` and :attr:`CollectConfig.qdd_source`.
SENSOR_NOISE = ("default", "none")
QDD_SOURCES = ("savgol", "true")
#: The presets of :attr:`CollectConfig.sensor_pipeline` (``"ideal+<factor>..."`` names are accepted too) and the
#: values of :attr:`CollectConfig.qdd_filter`.
SENSOR_PIPELINES = ("ideal", "jaco2")
QDD_FILTERS = ("centred", "causal")


def check_pipeline(name: object) -> None:
    """Raise ``ValueError`` naming ``sensor_pipeline`` unless ``name`` is a pipeline name the env accepts."""
    from jaco_env.signal_pipeline import FACTORS, SignalPipeline

    if not SignalPipeline.is_name(name):
        raise ValueError(f"sensor_pipeline: expected one of {SENSOR_PIPELINES} or 'ideal+' and factors of "
                         f"{tuple(FACTORS)} joined by '+', got {name!r}")
#: Fields added after the study data were collected, with the value those data had (for the reuse check).
_LATER_FIELDS = {"sensor_noise": "default", "qdd_source": "savgol", "sensor_pipeline": "ideal", "qdd_filter": None,
                 "link_inertials": None}


def sensor_model(sensor_noise: str):
    """The ``jaco_env.SensorNoise`` a collection with :attr:`CollectConfig.sensor_noise` records with."""
    from jaco_env import SensorNoise

    return SensorNoise.none() if sensor_noise == "none" else SensorNoise()


def sensor_std(sensor_noise: str) -> dict[str, float]:
    """The standard deviations of :func:`sensor_model` (stored in each file's ``meta["sensor_std"]``, so that the
    file is read right if the env's defaults change)."""
    sn = sensor_model(sensor_noise)
    return {"q_std": float(sn.q_std), "qd_std": float(sn.qd_std), "tau_std": float(sn.tau_std)}


def same_collection(stored: dict | None, cfg: CollectConfig) -> bool:
    """Whether a file's ``meta["collection"]`` was collected with ``cfg`` (files written before
    ``sensor_noise``/``qdd_source`` existed had their defaults)."""
    return isinstance(stored, dict) and {**_LATER_FIELDS, **stored} == asdict(cfg)


def collection_difference(stored: object, cfg: CollectConfig) -> str:
    """What differs between a file's ``meta["collection"]`` and ``cfg`` as :func:`same_collection` compares them."""
    have, want = ({**_LATER_FIELDS, **stored} if isinstance(stored, dict) else {}), asdict(cfg)
    return ", ".join(f"{k} {have.get(k)!r} (now {want.get(k)!r})" for k in sorted(set(have) | set(want))
                     if have.get(k) != want.get(k)) if have else "settings not recorded"


def nominal_urdf_for(data_meta: dict) -> Path:
    """The shipped nominal URDF (``jaco_env.nominal_urdf``) of the arm that recorded a collected file: its
    ``meta["collection"]`` resolved with :data:`_LATER_FIELDS` (files written before the link inertials existed
    were recorded with dm_control's), so a model's mean function has the link inertials of the simulated arm."""
    from jaco_env import nominal_urdf
    from jaco_env.link_inertials import resolve

    stored = data_meta.get("collection")
    if not isinstance(stored, dict):
        raise ValueError("meta['collection']: expected the collection's settings (a file of this module), "
                         f"got {type(stored).__name__}")
    merged = {**_LATER_FIELDS, **stored}
    return nominal_urdf(resolve(merged["link_inertials"], merged["sensor_pipeline"]))


PRESETS: dict[str, CollectConfig] = {
    "full": CollectConfig(),
    "quick": CollectConfig(n_subsets=3, subset_seconds=12.0, n_test=2, test_seconds=20.0),
    "smoke": CollectConfig(n_subsets=2, subset_seconds=3.0, n_test=1, test_seconds=4.0),
}


def motion_seed(cfg: CollectConfig, split: str, k: int) -> int:
    """Seed of motion ``k`` of ``split`` (``"train"``/``"test"``): distinct for every motion."""
    return int(cfg.seed) * 100_003 + (0 if split == "train" else 50_000) + int(k)


def _command_source(seed: int, duration: float) -> Callable[[float], np.ndarray]:
    """A seeded sum-of-sinusoids joint velocity command ``v(t) -> (6,)`` from ``jaco_env.excitation``."""
    from jaco_env import excitation

    return excitation.make_command(seed=seed, duration=duration)


def make_env(rate_hz: float, payload_mass: float, sensor_noise: str = "default", sensor_pipeline: str = "jaco2",
             link_inertials: str | None = None):
    """The collection's env: ``JacoPayload-v0`` in velocity mode at ``rate_hz``, no episode time limit;
    ``sensor_noise="none"``: noiseless measurements (see :attr:`CollectConfig.sensor_noise`);
    ``sensor_pipeline``, ``link_inertials``: the env's options of those names (see :class:`CollectConfig`)."""
    import gymnasium as gym

    import jaco_env  # noqa: F401  (registers the environments)

    if sensor_noise not in SENSOR_NOISE:
        raise ValueError(f"sensor_noise: expected one of {SENSOR_NOISE}, got {sensor_noise!r}")
    check_pipeline(sensor_pipeline)
    kw: dict = {"sensor_noise": None} if sensor_noise == "none" else {}
    kw["sensor_pipeline"] = sensor_pipeline
    if link_inertials is not None:
        kw["link_inertials"] = link_inertials
    return gym.make(ENV_ID, control_mode="velocity", control_freq=float(rate_hz),
                    payload_mass=float(payload_mass), max_episode_steps=10**9, **kw)


def _steps(duration: float, cfg: CollectConfig) -> tuple[int, int]:
    """(warm-up steps, recorded steps) of a motion of ``duration`` seconds."""
    return int(round(cfg.warmup_seconds * cfg.rate_hz)), int(round(duration * cfg.rate_hz))


def _record(seed: int, rows: np.ndarray, qacc: np.ndarray, cfg: CollectConfig, segment: int) -> DynamicsData:
    """The measured record of one motion from its observations ``rows`` and true accelerations ``qacc``."""
    n = 6
    q, qd, tau, t = rows[:, :n], rows[:, n:2 * n], rows[:, 2 * n:3 * n], rows[:, 3 * n]
    meta = {"robot": "jaco2-sim", "source": ENV_ID, "control_mode": "velocity",
            "payload_mass": float(cfg.payload_mass), "rate_hz": float(cfg.rate_hz), "seed": int(seed),
            "warmup_seconds": float(cfg.warmup_seconds)}
    data = DynamicsData.from_measurements(t, q, qd, tau, meta=meta,
                                          smoothing=cfg.smoothing,
                                          segment=np.full(t.shape, segment, dtype=np.int64))
    data.meta["qdd_error"] = qdd_error_stats(data.qdd, qacc)
    if cfg.qdd_source == "true":
        data = replace(data, qdd=qacc, meta={**data.meta, "qdd_source": "true joint accelerations of the "
                                              "simulator (info['qacc'], privileged)"})
    return data


def record_motion(seed: int, duration: float, cfg: CollectConfig, *, segment: int = 0,
                  desc: str = "", show_progress: bool = True, on_steps: Callable[[int], None] | None = None
                  ) -> DynamicsData:
    """Run one velocity-commanded motion and return its measured record (qdd differentiated).

    ``on_steps(k)``: called every 100 steps with the number of steps done since the last call."""
    env = make_env(cfg.rate_hz, cfg.payload_mass, cfg.sensor_noise, cfg.sensor_pipeline, cfg.link_inertials)
    try:
        obs, info = env.reset(seed=seed)
        command = _command_source(seed, duration)
        n_warm, n_steps = _steps(duration, cfg)
        dt = env.unwrapped.control_dt
        rows = np.empty((n_steps, obs.shape[0]))
        qacc = np.empty((n_steps, 6))
        for k in tqdm(range(n_warm + n_steps), desc=desc or f"motion seed {seed}", unit="step", leave=False,
                      mininterval=1.0, disable=not show_progress):
            obs, _, terminated, truncated, info = env.step(np.asarray(command(k * dt), dtype=np.float32))
            if info.get("unstable", False) or terminated:
                raise RuntimeError(f"motion seed {seed}: simulation became unstable/terminated at step {k}")
            if k >= n_warm:
                rows[k - n_warm] = obs
                qacc[k - n_warm] = info["qacc"]
            if on_steps is not None and (k + 1) % 100 == 0:
                on_steps(100)
    finally:
        env.close()
    return _record(seed, rows, qacc, cfg, segment)


def motion_job(seed: int, duration: float, cfg: dict, segment: int) -> DynamicsData:
    """One motion as a job of :func:`cascgp_experiments.execution.run_jobs` (progress in steps)."""
    from cascgp_experiments.execution import report_progress

    return record_motion(seed, duration, CollectConfig(**cfg), segment=segment, show_progress=False,
                         on_steps=report_progress)


def record_motions_vector(seeds: list[int], duration: float, cfg: CollectConfig, *, segments: list[int],
                          asynchronous: bool = True, bar: tqdm | None = None) -> list[DynamicsData]:
    """Run several motions of the same ``duration`` side by side in one Gymnasium vector env
    (:class:`gymnasium.vector.AsyncVectorEnv`: one process per motion; ``SyncVectorEnv``: all in this
    process). Every sub-env is reset with its motion's seed and stepped with its own command, so each
    record equals :func:`record_motion`'s for the same seed. ``bar``: advanced by one per motion step."""
    from functools import partial

    import gymnasium as gym

    n = len(seeds)
    fns = [partial(make_env, cfg.rate_hz, cfg.payload_mass, cfg.sensor_noise, cfg.sensor_pipeline,
                   cfg.link_inertials)] * n
    venv = (gym.vector.AsyncVectorEnv(fns, context="spawn") if asynchronous else gym.vector.SyncVectorEnv(fns))
    try:
        obs, info = venv.reset(seed=[int(s) for s in seeds])
        commands = [_command_source(s, duration) for s in seeds]
        n_warm, n_steps = _steps(duration, cfg)
        dt = venv.get_attr("control_dt")[0]
        rows = np.empty((n, n_steps, obs.shape[1]))
        qacc = np.empty((n, n_steps, 6))
        for k in range(n_warm + n_steps):
            action = np.stack([np.asarray(c(k * dt), dtype=np.float32) for c in commands])
            obs, _, terminated, truncated, info = venv.step(action)
            bad = np.asarray(info.get("unstable", np.zeros(n, bool)), bool) | np.asarray(terminated, bool)
            if bad.any():
                raise RuntimeError(f"motion seed {seeds[int(np.argmax(bad))]}: simulation became unstable/"
                                   f"terminated at step {k}")
            if k >= n_warm:
                rows[:, k - n_warm] = obs
                qacc[:, k - n_warm] = info["qacc"]
            if bar is not None:
                bar.update(n)
    finally:
        venv.close()
    return [_record(s, rows[i], qacc[i], cfg, seg) for i, (s, seg) in enumerate(zip(seeds, segments))]


def qdd_error_stats(qdd_est: np.ndarray, qdd_true: np.ndarray) -> dict:
    """Per joint: spread (std) and largest magnitude of the true accelerations, RMSE of the
    estimate, and the RMSE relative to the spread."""
    err = np.asarray(qdd_est) - np.asarray(qdd_true)
    spread = np.std(qdd_true, axis=0)
    rmse = np.sqrt(np.mean(err**2, axis=0))
    return {"true_qdd_std": spread.tolist(), "true_qdd_absmax": np.max(np.abs(qdd_true), axis=0).tolist(),
            "est_rmse": rmse.tolist(), "est_rmse_over_std": (rmse / np.maximum(spread, 1e-12)).tolist(),
            "n": int(len(err))}


def _motions(cfg: CollectConfig) -> list[tuple[str, int, int, float]]:
    """Every motion of the collection: ``(split, k, seed, seconds)``, training motions first."""
    out = []
    for split, count, seconds in (("train", cfg.n_subsets, cfg.subset_seconds), ("test", cfg.n_test, cfg.test_seconds)):
        out += [(split, k, motion_seed(cfg, split, k), seconds) for k in range(count)]
    return out


def _record_all(cfg: CollectConfig, workers: int, ray_address: str | None, vector_env: bool
                ) -> tuple[dict[str, list[DynamicsData]], dict | None]:
    """The records of every motion, by split, and the run's job statistics (``JobResults.stats``: one job
    per motion; ``None`` with ``vector_env``). ``workers=1``: one after the other in this process;
    otherwise one job per motion (:func:`motion_job`) on ``workers`` local processes or on Ray; with
    ``vector_env``, the motions of a split run ``workers`` at a time in one Gymnasium ``AsyncVectorEnv``
    instead. The records are the same in every case."""
    from cascgp_experiments.execution import JobResults, run_jobs

    motions = _motions(cfg)
    parts: dict[str, list[DynamicsData]] = {"train": [], "test": []}
    if ray_address is None and workers <= 1:
        serial = JobResults()
        serial.job_seconds, t0 = [], time.perf_counter()
        for split in ("train", "test"):
            mine = [m for m in motions if m[0] == split]
            for _, k, seed, seconds in tqdm(mine, desc=f"collect {split} ({len(mine)} x {mine[0][3]:g} s)",
                                            unit="motion"):
                t1 = time.perf_counter()
                parts[split].append(record_motion(seed, seconds, cfg, segment=k,
                                                  desc=f"{split} {k + 1}/{len(mine)}"))
                serial.append(None)
                serial.job_seconds.append(time.perf_counter() - t1)
        serial.wall_s = time.perf_counter() - t0
        return parts, serial.stats()
    elif ray_address is None and vector_env:
        with tqdm(total=sum(sum(_steps(m[3], cfg)) for m in motions), desc=f"collect, {workers} at a time",
                  unit="step", unit_scale=True, mininterval=1.0) as bar:
            for split in ("train", "test"):
                mine = [m for m in motions if m[0] == split]
                for b in range(0, len(mine), workers):
                    batch = mine[b:b + workers]
                    parts[split] += record_motions_vector([m[2] for m in batch], batch[0][3], cfg,
                                                          segments=[m[1] for m in batch], bar=bar)
        return parts, None
    res = run_jobs(motion_job, [{"seed": seed, "duration": seconds, "cfg": asdict(cfg), "segment": k}
                                    for _, k, seed, seconds in motions],
                   workers=workers, ray_address=ray_address, desc=f"collect ({len(motions)} motions)",
                   units=[sum(_steps(m[3], cfg)) for m in motions], unit="step",
                   label=lambda j: f"seed {j['seed']}")
    for (split, *_), data in zip(motions, res):
        parts[split].append(data)
    return parts, res.stats()


def _assemble(cfg: CollectConfig, split: str, parts: list[DynamicsData]) -> DynamicsData:
    """One split's file from its motions' records (pooled q̈ error statistics in ``meta``)."""
    meta = {**parts[0].meta, "split": split, "seeds": [p.meta["seed"] for p in parts],
            "collection": asdict(cfg), "sensor_std": sensor_std(cfg.sensor_noise),
            "qdd_error_per_motion": [p.meta["qdd_error"] for p in parts]}
    # Pooled over the motions (weighted by rows).
    ns = np.array([p.meta["qdd_error"]["n"] for p in parts], float)
    pooled_mse = sum(n * np.square(p.meta["qdd_error"]["est_rmse"]) for n, p in zip(ns, parts)) / ns.sum()
    meta["qdd_error"] = {"est_rmse": np.sqrt(pooled_mse).tolist(),
                         "true_qdd_std_per_motion_median": np.median(
                             [p.meta["qdd_error"]["true_qdd_std"] for p in parts], axis=0).tolist()}
    meta.pop("seed", None)
    return DynamicsData.concat(parts, meta=meta)


def data_path(folder: str | Path, split: str) -> Path:
    """The file of the collection's ``split`` (``"train"`` or ``"test"``) in ``folder``: ``jaco_<split>.npz``."""
    return Path(folder) / f"jaco_{split}.npz"


class OtherCollectionError(ValueError):
    """The output folder of :func:`collect` holds files of other settings (``replace_other=False``)."""


def collect(out: str | Path, cfg: CollectConfig = CollectConfig(), *, force: bool = False, workers: int | None = None,
            ray_address: str | None = None, vector_env: bool = False,
            replace_other: bool = True) -> tuple[DynamicsData, DynamicsData, dict]:
    """Collect (or reuse) ``<out>/jaco_train.npz`` and ``<out>/jaco_test.npz``.

    Files of the same settings are reused unless ``force``; files of other settings are replaced, or with
    ``replace_other=False`` (``cascgp collect``) refused, naming the settings that differ
    (:class:`OtherCollectionError`; ``force`` replaces them).

    ``workers``: motions simulated at once (``None``: every core), one job per motion on local processes
    or, with ``ray_address``, on a Ray cluster (:mod:`cascgp_experiments.execution`); ``vector_env``:
    the motions of a split ``workers`` at a time in a Gymnasium ``AsyncVectorEnv`` instead (slower here:
    see the module's notes). The data do not depend on any of these.
    Returns ``(train, test, info)`` with ``info = {"reused": bool, "wall_s": float, "jobs": dict | None}``
    (``jobs``: the job statistics of a new collection, also written with the versions and the machine to
    ``<out>/collection_run.json``; ``None`` when the files were reused or ``vector_env`` ran the motions).
    """
    from cascgp_experiments.execution import check_workers

    workers = check_workers(workers)
    out = Path(out)
    paths = {s: data_path(out, s) for s in ("train", "test")}
    loaded = {} if force else {s: DynamicsData.load(p) for s, p in paths.items() if p.exists()}
    other = {s: d.meta.get("collection") for s, d in loaded.items()
             if not same_collection(d.meta.get("collection"), cfg)}
    if len(loaded) == 2 and not other:
        return loaded["train"], loaded["test"], {"reused": True, "wall_s": 0.0, "jobs": None}
    if other and not replace_other:
        split, stored = next(iter(other.items()))
        raise OtherCollectionError(f"{out} holds a collection with other settings ({paths[split].name}: "
                                   f"{collection_difference(stored, cfg)}); pass --force to replace it, or choose "
                                   "another --out")
    t0 = time.perf_counter()
    parts, jobs = _record_all(cfg, workers, ray_address, vector_env)
    data = {}
    for split in ("train", "test"):
        data[split] = _assemble(cfg, split, parts[split])
        data[split].save(paths[split])
    info = {"reused": False, "wall_s": time.perf_counter() - t0, "jobs": jobs}
    write_json(out / "collection_run.json", {**info, "provenance": {"versions": package_versions(),
                                                                     "machine": machine_info()}})
    return data["train"], data["test"], info


def study_data(folder: str | Path | None, out: str | Path, *, preset: str = "quick", sensor_noise: str = "default",
               qdd_source: str = "savgol", workers: int | None = None) -> tuple[DynamicsData, DynamicsData]:
    """The study's ``jaco_train.npz``/``jaco_test.npz`` from ``folder``; without one, the collection ``preset``
    (:data:`PRESETS`) with ``sensor_noise`` and ``qdd_source`` (see
    :class:`CollectConfig`) recorded into ``<out>/data`` on ``workers`` processes
    (``None``: every core), or reused from there when present with the same settings.

    The collection options only apply to a new collection: with ``folder``, anything but the defaults is a
    ``ValueError`` (the files are used as they were recorded)."""
    if folder:
        if (sensor_noise, qdd_source) != ("default", "savgol"):
            raise ValueError(f"sensor_noise={sensor_noise!r}/qdd_source={qdd_source!r} only apply to a new "
                             f"collection, not to the files in {folder!s} (leave out the data folder)")
        return tuple(DynamicsData.load(data_path(folder, s)) for s in ("train", "test"))
    if preset not in PRESETS:
        raise ValueError(f"preset: expected one of {tuple(PRESETS)}, got {preset!r}")
    cfg = replace(PRESETS[preset], sensor_noise=sensor_noise, qdd_source=qdd_source)
    train, test, _ = collect(Path(out) / "data", cfg, workers=workers)
    return train, test
