"""cascgp_experiments: the paper's experiments as an importable package (the ``scripts/`` are its command lines).

It sits on top of both libraries (it imports ``cascgp`` and ``jaco_env``; neither imports it). Importing the
package imports nothing else, so the light modules stay light:

===================  ============================================================================
module               owns
===================  ============================================================================
common               study names and labels, grids, Table I computation and numbers, repo paths,
                     thread limits (numpy and ``cascgp.io`` only)
curves               the nRMSE-vs-seconds curve engine (jobs, process pool, cache, fit audit)
collect              the simulated Jaco data collection (sum-of-sinusoids, velocity mode)
analyses             optimiser iteration counts per joint, Spearman correlation of states and torques
study                the whole data-efficiency study (presets, ``run_study``, the SARCOS block)
claims               the paper's claims checked on ``results.json``
plots                figures, tables and CSVs from ``results.json`` alone (no torch/jaco_env)
audit_suite          the GP fit equivalence audit's data sets and report
transfer             the task-transfer experiment on ``JacoPour-v0`` (uses :mod:`cascgp.learning`)
nominal_urdf         the Jaco 2 nominal URDF (uses :mod:`cascgp.urdf_export`)
residual             what the nominal model misses on the simulated Jaco 2
video                MP4 videos of episodes: captioned recorder (runner callback), side by side
                     comparison of controllers (imageio + imageio-ffmpeg, extra ``video``)
===================  ============================================================================
"""
