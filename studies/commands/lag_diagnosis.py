"""Per-joint look inside the gated and ungated learners' models on "left" (issue 10; protocol and reading
rules in :mod:`studies.lag_diagnosis`).

Usage::

    # the protocol, seeds 0-7
    python -m studies.commands.lag_diagnosis --out out/lag_diagnosis \
        --reference docs/studies/gate_eval.json docs/studies/learner_divergence_seeds4-7.json
    python -m studies.commands.lag_diagnosis --out out/lag_diagnosis --seeds 0  # fewer seeds

    # step 2: data or fit?
    python -m studies.commands.lag_diagnosis --refit --out out/lag_refit \
        --reference docs/studies/learner_divergence.json docs/studies/learner_divergence_seeds4-7.json
    # step 3
    python -m studies.commands.lag_diagnosis --factorial --out out/lag_factorial \
        --reference docs/studies/lag_refit.json
    python -m studies.commands.lag_diagnosis --episodes --out out/lag_episodes  # step 4

Writes ``lag_diagnosis.json`` (every attempt with the per-joint diagnostics, the GL / UL rows, the causes'
counts) and ``lag_diagnosis.md`` (``--refit``: ``lag_refit.*``; ``--factorial``: ``lag_factorial.*``; ``--episodes``:
``lag_episodes.*``) to ``--out``; finished jobs are cached under ``--out/cache``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from cascgp.io import read_json
from cascgp_experiments.cli.options import check_output
from cascgp_experiments.execution import add_execution_args, check_args, session
from studies.lag_diagnosis import LAG_SEEDS, run_diagnosis
from studies.lag_steps import run_episodes, run_factorial, run_refit


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", type=Path, required=True, help="output folder")
    p.add_argument("--seeds", type=str, default=",".join(map(str, LAG_SEEDS)), help="comma-separated seeds")
    p.add_argument("--reference", type=Path, nargs="*", default=[],
                   help="earlier runs' JSONs (gate_eval, learner_divergence) to check the attempts against")
    p.add_argument("--refit", action="store_true",
                   help="step 2: refit each learner's last training set afresh (data or fit?); --reference: the "
                        "divergence experiment's JSONs")
    p.add_argument("--factorial", action="store_true",
                   help="step 3: which phase's data? (front, left) episodes from either learner, fitted afresh; "
                        "--reference: step 2's lag_refit.json")
    p.add_argument("--episodes", action="store_true",
                   help="step 4: what differs in the learners' 'left' episodes (torque residual vs the link-side "
                        "rigid-body model, deviation from the reference)")
    add_execution_args(p)
    a = p.parse_args(argv)
    check_args(p, a)
    check_output(p, a.out, "--out", "folder")
    try:
        seeds = tuple(int(s) for s in a.seeds.split(","))
    except ValueError:
        p.error(f"--seeds: expected comma-separated integers, got {a.seeds!r}")
    for r in a.reference:
        if not r.is_file():
            p.error(f"--reference: no file {r}")
    steps = {"refit": (run_refit, "lag_refit"), "factorial": (run_factorial, "lag_factorial"),
             "episodes": (run_episodes, "lag_episodes")}
    chosen = [k for k in steps if getattr(a, k)]
    if len(chosen) > 1:
        p.error(f"--{' and --'.join(chosen)}: one step at a time")
    run, name = steps[chosen[0]] if chosen else (run_diagnosis, "lag_diagnosis")
    if a.reference and run is run_episodes:
        p.error("--reference: step 4 (--episodes) has nothing to check against")
    try:
        refs = tuple(read_json(r) for r in a.reference)
    except (OSError, ValueError) as e:
        p.error(f"--reference: {e}")
    kw = {"references": refs} if run is not run_episodes else {}
    with session(a.ray, a.workers):
        res = run(a.out, seeds=seeds, workers=a.workers, ray_address=a.ray, **kw)
    print((a.out / f"{name}.md").read_text())
    print(f"wall {res['wall_seconds']:.0f} s; results: {a.out / f'{name}.json'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
