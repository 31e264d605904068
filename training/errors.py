"""The one exception root of :mod:`training` and its specific subclasses.

Every error that concerns a file names the file and the problem, so that the command line
can print it as one line (``facecast corpus: error: ...``).
"""

from __future__ import annotations

from assets.errors import (  # file problems are the assets edge's; training raises them too
    AlignmentFormatError,
    CorpusFormatError,
    FileProblem,
    MissingDependencyError,
    NotAudioError,
    NotVideoError,
    SilentAudioError,
    SynthesisError,
    TruncatedFileError,
    WrongSampleRateError,
)
from realtime_core.errors import ConfigError, FacecastError

__all__ = [
    "AlignmentFormatError",
    "ConfigError",
    "CorpusFormatError",
    "FileProblem",
    "LengthMismatchError",
    "MissingDependencyError",
    "NoFaceError",
    "NotAudioError",
    "NotVideoError",
    "SilentAudioError",
    "SynthesisError",
    "TrainingError",
    "TruncatedFileError",
    "WrongSampleRateError",
]


class TrainingError(FacecastError):
    """Root of the errors only the training package raises."""


class NoFaceError(FileProblem, TrainingError):
    """No face (or too few frames with a face) was found in a video."""


class LengthMismatchError(FileProblem, TrainingError):
    """A video's audio and picture differ in duration by more than the extractor accepts."""
