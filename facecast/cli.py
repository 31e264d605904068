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
import signal
import sys

from realtime_core.errors import FacecastError

# name -> module; order is the order shown in --help.
COMMANDS: dict[str, str] = {
    "demo": "facecast.commands.demo",
    "serve": "facecast.commands.serve",
    "view": "facecast.commands.view",
    "send": "facecast.commands.send",
    "record": "facecast.commands.record",
    "animate": "facecast.commands.animate",
    "render": "facecast.commands.render",
    "say": "facecast.commands.say",
    "rig": "facecast.commands.rig",
    "corpus": "facecast.commands.corpus",
    "extract": "facecast.commands.extract",
    "units": "facecast.commands.units",
    "phones": "facecast.commands.phones",
    "train": "facecast.commands.train",
    "readout": "facecast.commands.readout",
    "adapt": "facecast.commands.adapt",
    "eval": "facecast.commands.eval",
    "mu": "facecast.commands.mu",
    "fit-maps": "facecast.commands.fit_maps",
    "bench": "facecast.commands.bench",
    "perceptual": "facecast.commands.perceptual",
    "warm-up": "facecast.commands.warm_up",
}


class HelpFormatter(argparse.ArgumentDefaultsHelpFormatter, argparse.RawDescriptionHelpFormatter):
    """Shows defaults and keeps the descriptions' line breaks. A default is not appended where it would
    say nothing or say it twice: None, off flags, empty lists, required options, and help texts that
    already state their default in words ("(default: the config's, else 8765)"); nor on an off switch
    (``--no-energy``), whose default True would read as "off by default"."""

    def _get_help_string(self, action: argparse.Action) -> str | None:
        text = action.help or ""
        off_switch = isinstance(action, argparse._StoreFalseAction)
        if action.required or action.default in (None, False, [], ()) or off_switch or "(default" in text:
            return action.help
        return super()._get_help_string(action)


def _version() -> str:
    """The installed distribution's version (pyproject.toml), or "unknown" when run from a tree not installed."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("facecast")
    except PackageNotFoundError:
        return "unknown"


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="facecast",
        description="Real-time speech-driven facial animation of any 3D head.",
        formatter_class=HelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"facecast {_version()}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for module in COMMANDS.values():
        importlib.import_module(module).add_parser(sub)
    return parser


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised where the command is: it ends as on Ctrl-C (partial outputs removed, a take saved), exit 143."""


def _terminated(signum: int, frame: object) -> None:
    raise Terminated


def entry() -> int:
    """The console script: SIGTERM (`kill PID`, a job scheduler's stop) ends a command as Ctrl-C does; by default it
    killed the process where it stood (a render left its half-written `.NAME.tmp.mp4` beside the output). Commands
    that run an event loop (serve, demo) handle SIGTERM themselves. Not in :func:`main`: tests call it off the main
    thread, where no signal handler can be set."""
    signal.signal(signal.SIGTERM, _terminated)
    return main()


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    from facecast.commands.bench import FORWARDED, run_forwarded

    if len(argv) >= 2 and argv[0] == "bench" and argv[1] in FORWARDED:
        # Benchmarks with their own parsers get everything after their name (and the same one-line errors:
        # `bench latency --model missing.npz` was a traceback).
        command, run = "bench", lambda: run_forwarded(argv[1], argv[2:])
    else:
        args = build_parser().parse_args(argv)
        command, run = args.command, lambda: args.run(args)
    try:
        return int(run() or 0)
    except FacecastError as exc:  # the one root: a user-facing error prints one line, no traceback
        print(f"facecast {command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as exc:
        return 128 + signal.SIGTERM if isinstance(exc, Terminated) else 130
