"""``python -m cascgp_experiments.cli``: the ``cascgp`` command without its console script."""

import sys

from cascgp_experiments.cli import main

sys.exit(main())
