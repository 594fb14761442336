"""Kept for commands written before the ``cascgp`` console script: ``python -m scripts.sarcos_study ARGS`` is
``cascgp sarcos ARGS`` (:mod:`cascgp_experiments.cli.sarcos`)."""

from cascgp_experiments.cli.sarcos import main

if __name__ == "__main__":
    main()
