"""``facecast fit-maps``: re-fit the ARKit/OVR blendshape maps and the expression table (paper 002 eq. 4)."""

from __future__ import annotations

import argparse
from pathlib import Path

DEFAULT_OUT = Path(__file__).resolve().parents[2] / "realtime_core" / "fitted_maps.py"


def add_parser(sub: argparse._SubParsersAction) -> None:
    from facecast.cli import HelpFormatter

    p = sub.add_parser(
        "fit-maps",
        help="re-fit the blendshape maps and expression table from the built-in head's ARKit targets",
        formatter_class=HelpFormatter,
        description="Non-negative least squares (paper 002 eq. 4) of the built-in head's own ARKit morph targets "
        "to its rig's motion for each signed unit of each mouth parameter (a lowered upper lip and rounded lips also "
        "keeping the rig's lip gaps and mouth corners, so the lips stay closed at /m/); the OVR visemes' keyframes "
        "from their articulatory targets; each expression recipe's effect on the four mouth parameters, measured on "
        "the head. Writes the generated Python module the sans-I/O core reads (realtime_core/fitted_maps.py).",
    )
    p.add_argument("-o", "--output", type=Path, default=DEFAULT_OUT, help="the generated module")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from assets.files import atomic_write_bytes
    from assets.heads.builtin import load_builtin_head
    from assets.heads.rigfile import builtin_rig
    from training.fit_maps import fit_maps, module_text

    rig, _ = builtin_rig()
    atomic_write_bytes(args.output, module_text(fit_maps(load_builtin_head(), rig)).encode())
    print(f"wrote {args.output}")
    return 0
