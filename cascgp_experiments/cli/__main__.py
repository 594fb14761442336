"""``python -m cascgp_experiments.cli``: the ``cascgp`` command without its console script."""

import sys

from cascgp_experiments.cli import main

if __name__ == "__main__":  # importing the module (e.g. pkgutil.walk_packages) runs nothing
    sys.exit(main())
