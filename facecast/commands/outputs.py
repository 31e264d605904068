"""``-o OUT``: the output option of the commands that write animation files, the format chosen by the name's suffix
(``say``, ``animate``, ``record``): one option and one set of checks, so the commands take and refuse the same names."""

from __future__ import annotations

import argparse
from collections.abc import Iterable, Mapping
from pathlib import Path


def add_output_option(p: argparse.ArgumentParser, *, formats: str, repeatable: bool, required: bool) -> None:
    """``-o/--output OUT`` (dest ``output``: a list of paths if ``repeatable``, else one path or None); ``formats``:
    the suffixes it takes, for the help (checked by :func:`check_output_formats` when the command runs, so that
    building the parser imports no writer)."""
    p.add_argument(
        "-o",
        "--output",
        type=Path,
        action="append" if repeatable else "store",
        required=required,
        default=None,
        metavar="OUT",
        help=f"output file, {formats}: the format follows the suffix" + (" (repeatable)" if repeatable else ""),
    )


def check_output_formats(outs: Iterable[Path], formats: Iterable[str], hints: Mapping[str, str] | None = None) -> None:
    """Refuse (ExportError, before any work) the first of ``outs`` whose suffix is not one of ``formats``;
    ``hints``: a suffix -> what to do instead (e.g. which command writes it)."""
    from clients.export.errors import ExportError

    allowed = tuple(formats)
    for o in outs:
        suffix = o.suffix.lower()
        if suffix not in allowed:
            hint = (hints or {}).get(suffix, f"use {', '.join(allowed)}")
            raise ExportError(f"{o}: unknown output format {suffix or '(no suffix)'!r} ({hint})")


def check_distinct_outputs(outs: Iterable[Path]) -> None:
    """Refuse (ExportError, before any work) the second of ``outs`` that names the same file as an earlier one
    (resolved: ``a.csv`` and ``./a.csv``, a link to it): ``animate SPEECH -o a.csv -o a.csv`` wrote the file twice
    and printed "wrote a.csv" twice, and ``-o a.csv --csv a.csv`` the same."""
    from clients.export.errors import ExportError

    seen: dict[Path, Path] = {}
    for o in map(Path, outs):
        first = seen.get(o.resolve())
        if first is not None:
            same = "" if first == o else f" (as {first})"
            raise ExportError(f"{o}: given twice as an output{same}; give each output once")
        seen[o.resolve()] = o
