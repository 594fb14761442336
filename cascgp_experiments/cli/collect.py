"""Collect the simulated Jaco data set of the data-efficiency study (the paper's protocol).

Usage::

    cascgp collect --out out/study/data [--quick|--smoke] [--workers N | --ray ADDRESS] [--vector-env]
        [--sensor-noise none] [--qdd true] [--sensor-pipeline ideal] [--qdd-filter causal]
        [--link-inertials kinova]

The protocol and the files: :mod:`cascgp_experiments.collect`.
"""

from __future__ import annotations

import argparse
from dataclasses import asdict

from cascgp_experiments.cli.options import check_output, settings_error
from cascgp_experiments.collect import PRESETS, CollectConfig, OtherCollectionError, collect, data_path
from cascgp_experiments.execution import add_execution_args, check_args, session


def main(argv: list[str] | None = None, prog: str | None = None) -> None:
    """``cascgp collect``: parse ``argv`` (``sys.argv[1:]`` when ``None``) and run."""
    from jaco_env.link_inertials import LINK_INERTIALS

    ap = argparse.ArgumentParser(prog=prog, description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", required=True, help="folder for jaco_train.npz and jaco_test.npz")
    g = ap.add_mutually_exclusive_group()
    g.add_argument("--quick", action="store_true", help="3 x 12 s training, 2 x 20 s test")
    g.add_argument("--smoke", action="store_true", help="2 x 3 s training, 1 x 4 s test")
    ap.add_argument("--seed", type=int, default=0,
                    help="seed of the excitation motions and the sensor noise (default: 0)")
    ap.add_argument("--payload-mass", type=float, default=None, help="kg (default 0.8)")
    ap.add_argument("--sensor-noise", default="default", choices=("default", "none"),
                    help="the env's SensorNoise() (default) or noiseless sensors (an ablation)")
    ap.add_argument("--qdd", default="savgol", choices=("savgol", "true"),
                    help="q̈ from the Savitzky-Golay filter (default) or the simulator's true q̈ (an ablation)")
    ap.add_argument("--sensor-pipeline", default="jaco2",
                    help="the env's sensing pipeline: jaco2 (default: the real Jaco 2's; sources: the "
                         "documentation's Sensing sources page), ideal or ideal+FACTOR[+FACTOR...] with factors "
                         "skew, velocity, torque")
    ap.add_argument("--qdd-filter", default=None, choices=("centred", "causal"),
                    help="the Savitzky-Golay q̈ filter (default: causal under jaco2, else centred)")
    ap.add_argument("--link-inertials", default=None, choices=LINK_INERTIALS,
                    help="the arm's link inertials (default: kinova under jaco2, else dm_control); "
                         "fit with the nominal URDF of the same inertials")
    ap.add_argument("--force", action="store_true",
                    help="collect again even if files exist (also over files of other settings)")
    ap.add_argument("--vector-env", action="store_true",
                    help="run the motions of a split --workers at a time in one Gymnasium AsyncVectorEnv instead of "
                         "one job per motion (same data; slower here, the env steps are cheap)")
    add_execution_args(ap)
    a = ap.parse_args(argv)
    check_output(ap, a.out, "--out", "folder")
    check_args(ap, a)
    base = PRESETS["quick" if a.quick else "smoke" if a.smoke else "full"]
    kw = asdict(base) | {"seed": a.seed, "sensor_noise": a.sensor_noise, "qdd_source": a.qdd,
                         "sensor_pipeline": a.sensor_pipeline, "qdd_filter": a.qdd_filter,
                         "link_inertials": a.link_inertials}
    if a.payload_mass is not None:
        kw["payload_mass"] = a.payload_mass
    try:
        cfg = CollectConfig(**kw)
    except (ValueError, TypeError) as e:
        settings_error(ap, e, {"seed": "--seed", "payload_mass": "--payload-mass",
                               "sensor_pipeline": "--sensor-pipeline"})
    try:
        with session(a.ray, a.workers):
            train, test, info = collect(a.out, cfg, force=a.force, workers=a.workers, ray_address=a.ray,
                                        vector_env=a.vector_env, replace_other=False)
    except OtherCollectionError as exc:  # an --out folder of another collection: an argument error
        ap.error(str(exc))
    for split, d in (("train", train), ("test", test)):
        print(f"{data_path(a.out, split)}: {d.n_samples} samples, {len(d.segments)} motion(s), {d.dof} "
              f"joints, dt {d.dt:g} s")
    jobs = info["jobs"]
    print(f"reused the files in {a.out} (same settings; --force collects again)" if info["reused"]
          else f"collected in {info['wall_s']:.1f} s" + (
              f" ({jobs['n_jobs']} motions as jobs on {jobs['workers']} worker(s), {jobs['backend']}; the longest "
              f"{jobs['job_seconds_max']:.1f} s)" if jobs else ""))


if __name__ == "__main__":
    main()
