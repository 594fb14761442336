"""Generate the nominal URDFs of the simulated Jaco 2 arm (each with its JSON sidecar).

Usage::

    python -m scripts.generate_urdf --error 0.1 --seed 0

writes ``jaco_env/assets/jaco2_nominal.urdf`` (dm_control's link inertials) and
``jaco_env/assets/jaco2_nominal_kinova.urdf`` (Kinova's URDF link inertials), each with its ``.json``
(package data of ``jaco_env``); ``--out PATH --link-inertials NAME`` writes one model elsewhere. What is
exported and why: :mod:`cascgp_experiments.nominal_urdf`; the conversion, the calibration error rule and
the sidecar format: :mod:`cascgp_experiments.urdf_export`.
"""

from __future__ import annotations

import argparse

from cascgp_experiments.cli.options import check_output
from cascgp_experiments.nominal_urdf import DEFAULT_OUT, OUT_NAMES, write
from jaco_env.link_inertials import LINK_INERTIALS


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", default=None,
                        help="URDF path (the .json sidecar goes next to it); default: both committed models")
    parser.add_argument("--link-inertials", choices=LINK_INERTIALS, default="dm_control",
                        help="link inertials of the model written to --out")
    parser.add_argument("--error", type=float, default=0.1, help="relative calibration error e in [0, 1)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the calibration error")
    args = parser.parse_args(argv)
    check_output(parser, args.out, "--out", "file")
    targets = ([(args.out, args.link_inertials)] if args.out is not None
               else [(str(DEFAULT_OUT.with_name(name)), li) for li, name in OUT_NAMES.items()])
    for out, li in targets:
        urdf, js = write(out, args.error, args.seed, link_inertials=li)
        print(f"wrote {urdf} and {js}")


if __name__ == "__main__":
    main()
