"""Kept for commands written before the ``cascgp`` console script: ``python -m scripts.data_efficiency ARGS`` is
``cascgp study ARGS`` (:mod:`cascgp_experiments.cli.study`)."""

from cascgp_experiments.cli.study import main

if __name__ == "__main__":
    main()
