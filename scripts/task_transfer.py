"""Kept for commands written before the ``cascgp`` console script: ``python -m scripts.task_transfer ARGS`` is
``cascgp transfer ARGS`` (:mod:`cascgp_experiments.cli.transfer`)."""

from cascgp_experiments.cli.transfer import main

if __name__ == "__main__":
    main()
