"""Wall time of the experiments with 1 vs N workers (and on Ray), and what a cluster would take.

Each *case* is one experiment command (:data:`CASES`); it is run once per setting (``--workers 1``,
``--workers 2``, ``--ray local`` ...) in a fresh output folder, in a subprocess, and timed. Besides the
wall time, the results JSON of every run gives the job statistics of
:mod:`cascgp_experiments.execution` (number of jobs, seconds of each), and the numbers of the
experiment are compared with the first setting's (they must be identical).

Cluster estimate, from the serial run's measured job times: with ``k`` workers the jobs take at least
``max(longest job, sum of jobs / k)``; the rest of the serial run (collection, data preparation,
figures: its wall time minus the sum of its jobs) does not shrink. On a cluster of at least as many
cores as jobs, the longest job bounds the wall time.

The load average of the machine (other work on it) is recorded before and after every run.
Command line: ``python -m scripts.bench_parallel``.
"""

from __future__ import annotations

import os
import platform
import shutil
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

from cascgp.io import read_json, write_json

#: name -> (module, arguments; ``{out}`` is the run's output folder)
CASES: dict[str, tuple[str, list[str]]] = {
    "collect-full": ("scripts.collect_jaco_data", ["--out", "{out}", "--force"]),
    "transfer-quick": ("scripts.task_transfer", ["--quick", "--overwrite", "--out", "{out}"]),
    "transfer-full": ("scripts.task_transfer", ["--overwrite", "--out", "{out}"]),
    "study-max5": ("scripts.data_efficiency", ["--out", "{out}", "--max-seconds", "5", "--no-iterations"]),
    "study-max10": ("scripts.data_efficiency", ["--out", "{out}", "--max-seconds", "10", "--no-iterations"]),
    "study-quick": ("scripts.data_efficiency", ["--out", "{out}", "--quick"]),
    "study-full": ("scripts.data_efficiency", ["--out", "{out}"]),
}


def job_stats(module: str, out: Path) -> tuple[dict[str, Any], Any]:
    """(job statistics, the experiment's numbers) of one run's results JSON."""
    if module == "scripts.collect_jaco_data":  # the job statistics of collection_run.json; the files' arrays
        from cascgp_experiments.collect import data_path
        from cascgp_experiments.curves import npz_digest

        jobs = read_json(out / "collection_run.json")["jobs"] or {  # None: the motions ran in a vector env
            "n_jobs": 0, "job_seconds_sum": 0.0, "job_seconds_max": 0.0, "backend": "vector-env", "workers": None}
        return ({k: jobs[k] for k in ("n_jobs", "job_seconds_sum", "job_seconds_max", "backend", "workers")},
                {s: npz_digest(data_path(out, s)) for s in ("train", "test")})
    res = read_json(out / "results.json")
    if module == "scripts.task_transfer":
        numbers = {n: [{k: v for k, v in a.items() if k != "fit_seconds"} for a in att]
                   for n, att in res["controllers"].items()}
        blocks = [res["jobs"]]
    else:
        numbers = {b: {m: v["nrmse_all"] for m, v in res[b]["models"].items()} for b in ("jaco", "sarcos") if b in res}
        blocks = [res[b]["jobs"] for b in ("jaco", "sarcos") if b in res]
    secs = [s for b in blocks for s in b["job_seconds"] if s is not None]
    return {"n_jobs": len(secs), "job_seconds_sum": sum(secs), "job_seconds_max": max(secs) if secs else 0.0,
            "backend": blocks[0]["backend"], "workers": blocks[0]["workers"]}, numbers


def run_case(name: str, setting: list[str], root: Path) -> dict[str, Any]:
    module, args = CASES[name]
    out = root / f"{name}_{'_'.join(a.strip('-') for a in setting)}"
    shutil.rmtree(out, ignore_errors=True)
    cmd = [sys.executable, "-m", module, *[a.format(out=out) for a in args], *setting]
    load0 = os.getloadavg()
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    load1 = os.getloadavg()
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed:\n{proc.stderr[-3000:]}")
    stats, numbers = job_stats(module, out)
    return {"case": name, "setting": " ".join(setting), "command": "python -m " + " ".join(cmd[2:]),
            "wall_s": wall, "load_before": load0, "load_after": load1, **stats, "_numbers": numbers}


def cluster_estimate(serial: dict[str, Any], k: int) -> float:
    overhead = max(0.0, serial["wall_s"] - serial["job_seconds_sum"])
    return overhead + max(serial["job_seconds_max"], serial["job_seconds_sum"] / k)


def markdown(rows: list[dict[str, Any]]) -> str:
    lines = ["| case | setting | wall (s) | speed-up | jobs | sum of jobs (s) | longest job (s) | same numbers "
             "| load avg before/after |", "|---|---|---|---|---|---|---|---|---|"]
    first: dict[str, dict] = {}
    for r in rows:
        base = first.setdefault(r["case"], r)
        lines.append(f"| {r['case']} | {r['setting']} | {r['wall_s']:.0f} | {base['wall_s'] / r['wall_s']:.2f} "
                     f"| {r['n_jobs']} | {r['job_seconds_sum']:.0f} | {r['job_seconds_max']:.0f} "
                     f"| {'yes' if r['same_numbers'] else 'NO'} "
                     f"| {r['load_before'][0]:.1f} / {r['load_after'][0]:.1f} |")
    with_jobs = {name: base for name, base in first.items() if base["n_jobs"]}
    if with_jobs:
        lines += ["", "| case | jobs | longest job (s) | serial part (s) "
                      "| estimated wall, 2 / 8 / 32 / all-jobs cores (s) |",
                  "|---|---|---|---|---|"]
    for name, base in with_jobs.items():
        est = [cluster_estimate(base, k) for k in (2, 8, 32, max(1, base["n_jobs"]))]
        lines.append(f"| {name} | {base['n_jobs']} | {base['job_seconds_max']:.0f} "
                     f"| {max(0.0, base['wall_s'] - base['job_seconds_sum']):.0f} | "
                     + " / ".join(f"{e:.0f}" for e in est) + " |")
    return "\n".join(lines)


def run(cases: list[str], settings: list[list[str]], root: Path, json_path: Path | None) -> dict[str, Any]:
    rows = []
    for name in cases:
        ref = None
        for setting in settings:
            r = run_case(name, setting, root)
            numbers = r.pop("_numbers")
            ref = numbers if ref is None else ref
            r["same_numbers"] = numbers == ref
            rows.append(r)
            print(f"{name} {' '.join(setting)}: {r['wall_s']:.0f} s (load {r['load_before'][0]:.1f})", flush=True)
            if json_path is not None:  # after every run, so that a long benchmark keeps what it measured
                write_json(json_path, _report(rows))
    return _report(rows)


def _report(rows: list[dict[str, Any]]) -> dict[str, Any]:
    return {"machine": {"cpus": os.cpu_count(), "platform": platform.platform(), "python": platform.python_version()},
            "date": time.strftime("%Y-%m-%d %H:%M:%S"), "rows": rows, "table": markdown(rows)}
