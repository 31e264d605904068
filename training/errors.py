"""The one exception root of :mod:`training` and its specific subclasses.

Every error that concerns a file names the file and the problem, so that the command line
can print it as one line (``facecast corpus: error: ...``).
"""

from __future__ import annotations

from pathlib import Path


class TrainingError(Exception):
    """Root of every error raised by the training package."""


class ConfigError(TrainingError, ValueError):
    """A configuration value is out of range or inconsistent."""


class FileProblem(TrainingError):
    """A problem with one input or corpus file; ``path`` names it and ``problem`` says what."""

    def __init__(self, path: str | Path, problem: str) -> None:
        self.path = Path(path)
        self.problem = problem
        super().__init__(f"{self.path}: {problem}")


class NotAudioError(FileProblem):
    """The file is not a readable audio file (or has no audio stream)."""


class SilentAudioError(FileProblem):
    """The audio holds no signal (all samples at or near zero)."""


class WrongSampleRateError(FileProblem):
    """The audio's sample rate is not one the corpus accepts or not the one declared."""


class TruncatedFileError(FileProblem):
    """The file ends early: a truncated WAV or video, or fewer rows/frames than declared."""


class NoFaceError(FileProblem):
    """No face (or too few frames with a face) was found in a video."""


class CorpusFormatError(FileProblem):
    """A corpus file (manifest, params.csv, phonemes.json) does not follow the layout."""


class AlignmentFormatError(FileProblem):
    """A phone-alignment file (.lab, TextGrid, phone JSON) cannot be parsed."""


class SynthesisError(TrainingError):
    """espeak-ng failed: library missing, unknown voice, or synthesis error."""


class MissingDependencyError(TrainingError):
    """An optional dependency (e.g. mediapipe for video) or tool (ffmpeg) is not installed."""


class NotVideoError(FileProblem):
    """The file is not a readable video (no video stream, unknown format)."""


class LengthMismatchError(FileProblem):
    """A video's audio and picture differ in duration by more than the extractor accepts."""
