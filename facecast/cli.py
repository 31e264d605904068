"""The ``facecast`` command line: the only place where argv becomes configuration.

Each subcommand lives in ``facecast/commands/<name>.py`` with two functions:
``add_parser(subparsers)`` declares its options (every option has a help text and its
default is shown) and ``run(args) -> int`` turns them into the frozen configuration
objects of the library and calls it. Heavy imports happen inside ``run`` so that
``facecast --help`` stays fast and a missing optional dependency only affects its command.
"""

from __future__ import annotations

import argparse
import importlib
import sys

# name -> module; order is the order shown in --help.
COMMANDS: dict[str, str] = {
    "demo": "facecast.commands.demo",
    "serve": "facecast.commands.serve",
    "view": "facecast.commands.view",
    "record": "facecast.commands.record",
    "animate": "facecast.commands.animate",
    "render": "facecast.commands.render",
    "rig": "facecast.commands.rig",
    "corpus": "facecast.commands.corpus",
    "extract": "facecast.commands.extract",
    "train": "facecast.commands.train",
    "eval": "facecast.commands.eval",
    "bench": "facecast.commands.bench",
}


class HelpFormatter(argparse.ArgumentDefaultsHelpFormatter, argparse.RawDescriptionHelpFormatter):
    """Shows defaults and keeps the descriptions' line breaks."""


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="facecast",
        description="Real-time speech-driven facial animation of any 3D head.",
        formatter_class=HelpFormatter,
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for module in COMMANDS.values():
        importlib.import_module(module).add_parser(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    # Benchmarks forwarded to their own modules take options facecast does not know.
    args, extra = parser.parse_known_args(argv)
    if extra:
        if not hasattr(args, "args"):
            parser.error(f"unrecognized arguments: {' '.join(extra)}")
        args.args = [*args.args, *extra]
    # Package error roots: a user-facing error prints one line, never a traceback.
    roots: list[type[BaseException]] = []
    for mod, name in (
        ("realtime_core.errors", "RealtimeCoreError"),
        ("training.errors", "TrainingError"),
        ("server.errors", "ServerError"),
        ("clients.errors", "ClientError"),
    ):
        try:
            roots.append(getattr(importlib.import_module(mod), name))
        except ImportError:
            continue
    try:
        return int(args.run(args) or 0)
    except tuple(roots) as exc:  # type: ignore[misc]
        print(f"facecast {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130
