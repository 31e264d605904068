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

SHIPPED = Path(__file__).resolve().parent / "data" / "grid_s1_units.npz"
"""The unit corpus shipped with facecast (GRID s1 train + val; ``facecast units build --ship``)."""


def cache_folder(cache_dir: str | Path | None = None) -> Path:
    """Where built corpora are cached: ``$FACECAST_CACHE/unitsel`` (or ``~/.cache/facecast/unitsel``)."""
    import os

    if cache_dir is not None:
        return Path(cache_dir) / "unitsel"
    env = os.environ.get("FACECAST_CACHE")
    return (Path(env).expanduser() if env else Path.home() / ".cache" / "facecast") / "unitsel"


def find_unit_corpus(path: str | Path | None = None) -> Path:
    """The corpus file to use: ``path`` if given, else the shipped one, else the newest built one
    in the cache; raises UnitCorpusFileError saying how to build one."""
    if path is not None:
        return Path(path)
    if SHIPPED.is_file():
        return SHIPPED
    built = sorted(cache_folder().glob("grid_s1_units-*.npz"), key=lambda p: p.stat().st_mtime)
    if built:
        return built[-1]
    raise UnitCorpusFileError(
        SHIPPED,
        "no unit corpus shipped or built; run `facecast units build` (needs the "
        "GRID s1 videos and their extraction) or pass --corpus",
    )


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
