"""Model files on disk: atomic save, load naming the file, and the shipped default model.

The format itself (``.npz``, no pickle, versioned, validated) is
:mod:`realtime_core.avmodel`; this module is only the file edge.
"""

from __future__ import annotations

from pathlib import Path

from assets.errors import FileProblem
from assets.files import atomic_write_bytes
from realtime_core.avmodel import AvModel, decode_model, encode_model
from realtime_core.errors import ModelFormatError

DEFAULT_MODEL = Path(__file__).resolve().parent / "data" / "default_model.npz"
"""The model every command uses when none is given (trained by ``scripts/train_default_model.sh``)."""


class ModelFileError(FileProblem):
    """A model file is missing, unreadable or invalid (the message names file and problem)."""


def save_model(path: str | Path, model: AvModel) -> Path:
    """Write ``model`` to ``path`` atomically (temporary file + rename)."""
    path = Path(path)
    atomic_write_bytes(path, encode_model(model))
    return path


def load_model(path: str | Path | None = None) -> AvModel:
    """Load and validate a model file; ``None`` loads the shipped default model."""
    path = DEFAULT_MODEL if path is None else Path(path)
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        hint = " (the default model ships with facecast; reinstall or pass --model)" if path == DEFAULT_MODEL else ""
        raise ModelFileError(path, f"model file not found{hint}") from None
    except OSError as exc:
        raise ModelFileError(path, f"cannot be read ({exc.strerror or exc})") from None
    try:
        return decode_model(data)
    except ModelFormatError as exc:
        raise ModelFileError(path, f"invalid model: {exc}") from None
