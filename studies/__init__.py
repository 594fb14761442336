"""Research studies built on the product (``cascgp``, ``jaco_env``, ``cascgp_experiments``).

Not part of the installed distribution: run from a checkout (``python -m studies.commands.<study>``). Each
study's protocol is in its module docstring and its write-up, with the results, under ``docs/studies/``.
"""
