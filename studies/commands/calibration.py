"""Calibration of the cascades' 95 % predictive intervals on held-out Jaco episodes (issue 10).

    python -m studies.commands.calibration --data out/study/data --out out/calibration [--seconds 10 30] [--subsets 3]
    python -m studies.commands.calibration --collect full --sensor-noise none --out out/cal/noiseless [...]

``--data`` is a folder with the study's ``jaco_train.npz``/``jaco_test.npz`` (``python -m
scripts.collect_jaco_data``); without it the ``--collect`` preset (default ``quick``) is recorded into
``<out>/data`` (or reused from there), with ``--sensor-noise none`` noiseless and ``--qdd true`` with the
simulator's true q̈ (the ablations of ``docs/studies/calibration.md``). ``--noise-floor sensor`` bounds every joint GP's
noise variance below by the torque sensor's (the noise-floor test of ``docs/studies/calibration.md``); ``--recalibrate``
scales each joint's std by a factor fitted on an unseen training motion (the recalibration test there).
Writes ``calibration.json`` and ``calibration.md`` into ``--out`` (see :mod:`studies.calibration`).
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

from cascgp_experiments.cli.options import check_input, check_output

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=None, help="folder with jaco_train.npz and jaco_test.npz")
    ap.add_argument("--out", required=True)
    ap.add_argument("--seconds", type=float, nargs="+", default=[10.0, 30.0])
    ap.add_argument("--subsets", type=int, default=3)
    ap.add_argument("--restarts", type=int, default=3)
    ap.add_argument("--collect", default="quick", help="collection preset when there is no --data (default quick)")
    ap.add_argument("--sensor-noise", default="default", choices=("default", "none"),
                    help="new collection only: the env's SensorNoise() or noiseless sensors")
    ap.add_argument("--qdd", default="savgol", choices=("savgol", "true"),
                    help="new collection only: q̈ from the Savitzky-Golay filter or the simulator's true q̈")
    ap.add_argument("--workers", type=int, default=None, help="collection processes (default: every core)")
    ap.add_argument("--input-noise", action="store_true",
                    help="also score the propagated variance plus the test-time input-noise term, with the sensor "
                         "noise and the filter gain of the data's collection (sensor_input_var)")
    ap.add_argument("--noise-floor", default="none", choices=("none", "sensor"),
                    help="lower bound of every joint GP's noise variance: none (default) or the torque sensor's "
                         "noise variance tau_std^2 of the data's collection (sensor_torque_var; 0.01 N^2 m^2)")
    ap.add_argument("--recalibrate", action="store_true",
                    help="also fit a per-joint std factor on an unseen training motion (motion n_subsets + k for "
                         "subset k) and score the test coverage with it (the recalibration test of "
                         "docs/studies/calibration.md)")
    a = ap.parse_args(argv)
    check_output(ap, a.out, "--out", "folder")
    if a.data and (a.sensor_noise != "default" or a.qdd != "savgol" or a.collect != "quick"):
        ap.error("--collect/--sensor-noise/--qdd apply to a new collection: leave out --data")
    check_input(ap, a.data, "--data", "folder", contains=("jaco_train.npz", "jaco_test.npz"))
    if a.recalibrate and not 1 <= a.subsets <= 5:
        ap.error(f"--recalibrate: --subsets must be 1-5 (each subset needs an unseen training motion of the 10), "
                 f"got {a.subsets}")
    import time

    import torch
    from tqdm import tqdm

    from cascgp_experiments.collect import study_data
    from studies.calibration import (CASCADES, calibration, recalibration_effect, sensor_input_var,
                                     sensor_torque_var, summary_table, write)

    torch.set_num_threads(1)
    out = Path(a.out)
    try:
        train, test = study_data(a.data, out, preset=a.collect, sensor_noise=a.sensor_noise, qdd_source=a.qdd,
                                 workers=a.workers)
    except ValueError as e:
        ap.error(str(e))
    input_var = None
    if a.input_noise:
        try:
            input_var = sensor_input_var(train.meta.get("collection"), train.dof, train.meta.get("sensor_std"))
        except ValueError as e:
            ap.error(f"--input-noise: {e}")
    floor = None
    if a.noise_floor == "sensor":
        try:
            floor = sensor_torque_var(train.meta.get("collection"), train.meta.get("sensor_std"))
        except ValueError as e:
            ap.error(f"--noise-floor: {e}")
    t0 = time.perf_counter()
    bar = tqdm(total=len(CASCADES) * len(a.seconds) * min(a.subsets, 10), desc="calibration fits")
    res = calibration(train, test, seconds=tuple(a.seconds), n_subsets=a.subsets, n_restarts=a.restarts,
                      input_var=input_var, noise_var_floor=floor, recalibrate=a.recalibrate,
                      progress=lambda row: bar.update())
    bar.close()
    res["wall_s"] = time.perf_counter() - t0
    res["command"] = "python -m studies.commands.calibration " + " ".join(argv if argv is not None
                                                                  else __import__("sys").argv[1:])
    write(res, out)
    print(summary_table(res))
    if a.recalibrate:
        print(recalibration_effect(res))
    print(f"wrote {out / 'calibration.json'}")


if __name__ == "__main__":
    main()
