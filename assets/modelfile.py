"""Model files on disk: atomic save, load naming the file, and the shipped default model.

The formats themselves (``.npz``, no pickle, versioned, validated) are :mod:`realtime_core.avmodel`
(the HMM) and :mod:`realtime_core.mapping.model` (the MLP mapper of paper 002); this module is only
the file edge. :func:`load_speech_model` picks the reader by ``--mapper hmm|mlp``.
"""

from __future__ import annotations

from pathlib import Path

from assets.errors import FileProblem
from assets.files import atomic_write_bytes, check_writable
from realtime_core.avmodel import AvModel, decode_model, encode_model
from realtime_core.errors import ConfigError, ModelFormatError
from realtime_core.mapping import MAPPER_KINDS, MlpSpeechModel, SpeechModel, decode_mlp_model, encode_mlp_model

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


DEFAULT_MLP_MODEL = Path(__file__).resolve().parent / "data" / "mlp_mapper.npz"
"""The MLP mapper ``--mapper mlp`` uses when no file is given: paper 002's GMM-selected MLP bank trained
by ``facecast mu`` on GRID s1 (Cooke, Barker, Cunningham, Shao 2006, CC BY 4.0; ``docs/motion_units.md``)."""


def check_model_output(path: str | Path) -> Path:
    """``path`` as a Path, or ModelFileError unless it ends in .npz; called before any work. A model
    written as ``my.json`` is still an npz archive that no reader takes for one, and ``-o low-latency``
    would write a file that ``--model low-latency`` never reads (a shipped name wins over a file)."""
    path = Path(path)
    if path.suffix.lower() != ".npz":
        raise ModelFileError(path, "a model file is written as .npz; give a name ending in .npz")
    return check_writable(path)  # a folder or a read-only place refuses now, not after the training


def save_model(path: str | Path, model: AvModel) -> Path:
    """Write ``model`` to ``path`` atomically (temporary file + rename)."""
    path = Path(path)
    atomic_write_bytes(path, encode_model(model))
    return path


def _read(path: Path) -> bytes:
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        if path in SHIPPED_MODELS.values():
            hint = " (shipped models come with facecast; reinstall or pass --model FILE)"
        else:  # a mistyped shipped name reads as a missing file: say which names there are
            hint = f" (nor a shipped name: {', '.join(SHIPPED_MODELS)})"
        raise ModelFileError(path, f"model file not found{hint}") from None
    except OSError as exc:
        raise ModelFileError(path, f"cannot be read ({exc.strerror or exc})") from None
    return data


def load_model(path: str | Path | None = None) -> AvModel:
    """Load and validate a model file; ``None`` loads the shipped default model, a shipped name
    (``"low-latency"``, :func:`resolve_model`) that model."""
    path = resolve_model(path)
    data = _read(path)
    try:
        return decode_model(data)
    except ModelFormatError as exc:
        raise ModelFileError(path, f"invalid model: {exc}") from None


def save_mlp_model(path: str | Path, model: MlpSpeechModel) -> Path:
    """Write an MLP mapper file atomically."""
    path = Path(path)
    atomic_write_bytes(path, encode_mlp_model(model))
    return path


def load_mlp_model(path: str | Path) -> MlpSpeechModel:
    """Load and validate an MLP mapper file (``facecast mu`` writes one); a file of another kind or
    version is refused naming the file and what it is. A shipped model's name (``--mapper mlp --model
    low-latency``) reads that file, to be refused as an HMM model rather than reported missing."""
    path = resolve_model(path)
    data = _read(path)
    try:
        return decode_mlp_model(data)
    except (ModelFormatError, ConfigError) as exc:
        raise ModelFileError(path, f"invalid MLP mapper: {exc}") from None


def load_speech_model(mapper: str = "hmm", path: str | Path | None = None) -> SpeechModel:
    """The model behind ``--mapper``: "hmm" (``path`` or the shipped HMM) or "mlp" (``path`` or the shipped
    MLP mapper)."""
    if mapper not in MAPPER_KINDS:
        raise ConfigError(f"mapper must be one of {', '.join(MAPPER_KINDS)}, got {mapper!r}")
    if mapper == "hmm":
        return load_model(path)
    if path is None:
        if not DEFAULT_MLP_MODEL.is_file():
            raise ConfigError("--mapper mlp needs a mapper file (--model MAPPER.npz, written by `facecast mu`)")
        path = DEFAULT_MLP_MODEL
    return load_mlp_model(path)
