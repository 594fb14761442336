"""cascgp_experiments: the paper's experiments as an importable package, and the ``cascgp`` command (``cli``).

It sits on top of both libraries (it imports ``cascgp`` and ``jaco_env``; neither imports it). Importing the
package imports nothing else, so the light modules stay light:

===================  ============================================================================
module               owns
===================  ============================================================================
cli                  the ``cascgp`` console script: fit / evaluate / predict and the experiments' commands
common               study names and labels, grids, Table I computation and numbers, the shipped nominal
                     URDF's path, the SARCOS default, thread limits (numpy and ``cascgp.io`` only)
execution            the parallel job layer (local processes / Ray, resume, retry, progress)
job_cache            the job layer's cache: one JSON file per finished job, keyed by function and inputs
ray_backend          the job layer's Ray backend (connection, token authentication, Ray tasks)
curves               the nRMSE-vs-seconds curve engine (one job per subset and standard model with its cascades;
                     fit audit)
collect              the simulated Jaco data collection (sum-of-sinusoids, velocity mode; one job per motion)
analyses             optimiser iteration counts per joint, Spearman correlation of states and torques
study                the whole data-efficiency study (presets, ``run_study``, the SARCOS block)
claims               the paper's claims checked on ``results.json``
pooled_stats         the study's primary tests: paired comparisons pooled over joints, Holm-corrected
compare              two runs of an experiment side by side (how far apart their numbers are)
plots                figures, tables and CSVs from ``results.json`` alone (no torch/jaco_env)
audit_suite          the GP fit equivalence audit's data sets and report
transfer             the task-transfer experiment on ``JacoPour-v0`` (uses :mod:`cascgp.learning`)
urdf_export          a compiled MuJoCo arm model -> URDF + JSON sidecar (conversion, seeded calibration error)
nominal_urdf         the Jaco 2 nominal URDF (uses :mod:`cascgp_experiments.urdf_export`)
residual             what the nominal model misses on the simulated Jaco 2
parallel_bench       wall time of the experiments with 1 vs N workers (``scripts.bench_parallel``)
run_hooks            retrain-loop hooks: paired controllers on one model, the GP seed offset
soak                 the long-run reliability soak (episodes, resets, make/close, retrains; memory)
video                MP4 videos of episodes: captioned recorder (runner callback), side by side
                     comparison of controllers (imageio + imageio-ffmpeg, extra ``video``)
===================  ============================================================================

The research studies built on these (gate rules, calibration, learner divergence) live in the checkout's
``studies/`` folder, not in the installed distribution.
"""
