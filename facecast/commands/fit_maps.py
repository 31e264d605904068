"""``facecast fit-maps``: re-fit the ARKit/OVR blendshape maps and the expression table (paper 002 eq. 4)."""

from __future__ import annotations

import argparse
from pathlib import Path

REGENERATE = "facecast fit-maps -o realtime_core/fitted_maps.py --into-package"
"""How the repository regenerates the module the core reads (from the checkout's root; docs/motion_units.md)."""


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
        "the head. Writes a generated Python module like the one the sans-I/O core reads "
        f"(realtime_core/fitted_maps.py; the repository regenerates it with `{REGENERATE}`).",
    )
    p.add_argument("-o", "--output", type=Path, required=True, help="the generated module (.py) to write")
    p.add_argument(
        "--into-package",
        action="store_true",
        help="allow the output inside facecast's own installed packages (the repository regenerating "
        "realtime_core/fitted_maps.py); without it such an output is refused",
    )
    p.set_defaults(run=run)


def _package_holding(path: Path) -> str | None:
    """The name of the facecast package whose folder holds ``path`` (None: none does)."""
    from importlib.util import find_spec

    from facecast import PACKAGES

    target = path.resolve()
    for name in PACKAGES:
        spec = find_spec(name)
        for folder in (spec.submodule_search_locations or ()) if spec is not None else ():
            if target.is_relative_to(Path(folder).resolve()):
                return name
    return None


def run(args: argparse.Namespace) -> int:
    from assets.errors import CannotWriteError
    from assets.files import atomic_write_bytes, check_writable
    from assets.heads.builtin import load_builtin_head
    from assets.heads.rigfile import builtin_rig
    from training.fit_maps import fit_maps, module_text

    package = _package_holding(args.output)
    # The default once wrote into the installed realtime_core, so running it from an installed facecast
    # silently replaced library code; refused before the fit, which takes seconds.
    if package is not None and not args.into_package:
        raise CannotWriteError(
            args.output, f"inside the installed facecast package {package!r}: not written (give --into-package)"
        )
    check_writable(args.output)  # before the fit, not after it
    rig, _ = builtin_rig()
    atomic_write_bytes(args.output, module_text(fit_maps(load_builtin_head(), rig)).encode())
    print(f"wrote {args.output}")
    return 0
