"""Model files on disk: atomic save, load naming the file, and the shipped default model.

The format itself (``.npz``, no pickle, versioned, validated) is
:mod:`realtime_core.avmodel`; this module is only the file edge.
"""

from __future__ import annotations

from pathlib import Path

from realtime_core.avmodel import AvModel, decode_model, encode_model
from realtime_core.errors import ModelFormatError
from assets.files import atomic_write_bytes
from assets.errors import FileProblem

DEFAULT_MODEL = Path(__file__).resolve().parent / "data" / "default_model.npz"
"""The model every command uses when none is given (trained by ``scripts/train_default_model.sh``)."""

LOW_LATENCY_MODEL = Path(__file__).resolve().parent / "data" / "low_latency_model.npz"
"""The shipped low-latency model: 78 ms algorithmic delay instead of 167 ms (t_c = 1, a 1.35-hop
window; trained by ``scripts/train_low_latency_model.sh``, docs/default_model.md)."""

SHIPPED_MODELS: dict[str, Path] = {"default": DEFAULT_MODEL, "low-latency": LOW_LATENCY_MODEL}
"""Names accepted wherever a model file is (``--model low-latency``) -> the shipped file."""


def resolve_model(spec: str | Path | None) -> Path:
    """The file of a model given as ``None`` (the default), a shipped name (:data:`SHIPPED_MODELS`;
    a name wins over a file of that name in the working directory: write ``./low-latency`` for
    that) or a path. The one place model names are resolved."""
    if spec is None:
        return DEFAULT_MODEL
    return SHIPPED_MODELS.get(str(spec), Path(spec))


class ModelFileError(FileProblem):
    """A model file is missing, unreadable or invalid (the message names file and problem)."""


def save_model(path: str | Path, model: AvModel) -> Path:
    """Write ``model`` to ``path`` atomically (temporary file + rename)."""
    path = Path(path)
    atomic_write_bytes(path, encode_model(model))
    return path


def load_model(path: str | Path | None = None) -> AvModel:
    """Load and validate a model file; ``None`` loads the shipped default model, a shipped name
    (``"low-latency"``, :func:`resolve_model`) that model."""
    path = resolve_model(path)
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        shipped = path in SHIPPED_MODELS.values()
        hint = " (shipped models come with facecast; reinstall or pass --model FILE)" if shipped else ""
        raise ModelFileError(path, f"model file not found{hint}") from None
    except OSError as exc:
        raise ModelFileError(path, f"cannot be read ({exc.strerror or exc})") from None
    try:
        return decode_model(data)
    except ModelFormatError as exc:
        raise ModelFileError(path, f"invalid model: {exc}") from None
