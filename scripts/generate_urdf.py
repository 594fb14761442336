"""Generate the nominal URDF of the simulated Jaco 2 arm (plus its JSON sidecar).

Usage::

    python -m scripts.generate_urdf --error 0.1 --seed 0

writes ``jaco_env/assets/jaco2_nominal.urdf`` and ``.json`` (package data of ``jaco_env``). What is exported and why:
:mod:`cascgp_experiments.nominal_urdf`; the conversion, the calibration error rule and the sidecar
format: :mod:`cascgp_experiments.urdf_export`.
"""

from __future__ import annotations

import argparse

from cascgp_experiments.nominal_urdf import DEFAULT_OUT, write


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", default=str(DEFAULT_OUT), help="URDF path (the .json sidecar goes next to it)")
    parser.add_argument("--error", type=float, default=0.1, help="relative calibration error e in [0, 1)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the calibration error")
    args = parser.parse_args(argv)
    urdf, js = write(args.out, args.error, args.seed)
    print(f"wrote {urdf} and {js}")


if __name__ == "__main__":
    main()
