"""Unit-selection corpus files on disk: atomic save and a load that names the file.

The format itself (``.npz``, no pickle, versioned, validated) is
:func:`realtime_core.synthesis.corpus.encode_corpus`; this module is only the file edge.
"""

from __future__ import annotations

from pathlib import Path

from assets.errors import FileProblem
from assets.files import atomic_write_bytes
from realtime_core.errors import ModelFormatError
from realtime_core.synthesis.corpus import StoredCorpus, decode_corpus, encode_corpus


class UnitCorpusFileError(FileProblem):
    """A unit-corpus file is missing, unreadable or invalid (the message names file and problem)."""


def save_unit_corpus(path: str | Path, stored: StoredCorpus) -> Path:
    """Write ``stored`` to ``path`` atomically (temporary file + rename)."""
    return atomic_write_bytes(Path(path), encode_corpus(stored))


def load_unit_corpus(path: str | Path) -> StoredCorpus:
    """Load and validate a unit-corpus file."""
    path = Path(path)
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise UnitCorpusFileError(path, "unit corpus file not found") from None
    except OSError as exc:
        raise UnitCorpusFileError(path, f"cannot be read ({exc.strerror or exc})") from None
    try:
        return decode_corpus(data)
    except ModelFormatError as exc:
        raise UnitCorpusFileError(path, str(exc)) from None
