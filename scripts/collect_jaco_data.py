"""Kept for commands written before the ``cascgp`` console script: ``python -m scripts.collect_jaco_data ARGS`` is
``cascgp collect ARGS`` (:mod:`cascgp_experiments.cli.collect`)."""

from cascgp_experiments.cli.collect import main

if __name__ == "__main__":
    main()
