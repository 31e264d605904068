"""Errors of the file and asset edge (:mod:`assets`), under :class:`realtime_core.errors.FacecastError`.

Every error that concerns a file names the file and the problem, so the command line can print it
as one line (``facecast render: error: head.obj: no faces``).
"""

from __future__ import annotations

from pathlib import Path

from realtime_core.errors import FacecastError


class AssetsError(FacecastError):
    """Root of every error raised by the assets package."""


class FileProblem(AssetsError):
    """A problem with one input file; ``path`` names it and ``problem`` says what."""

    def __init__(self, path: str | Path, problem: str) -> None:
        self.path = Path(path)
        self.problem = problem
        super().__init__(f"{self.path}: {problem}")


class CannotWriteError(FileProblem):
    """An output cannot be written where it was asked for: its folder is a file, no permission, disk full."""


class NotAudioError(FileProblem):
    """The file is not a readable audio file (or has no audio stream)."""


class UnsupportedWavError(NotAudioError):
    """A RIFF/WAVE file in an encoding the built-in PCM reader does not decode (float, 24-bit or
    multichannel WAVE_FORMAT_EXTENSIBLE, mu-law ...); :func:`assets.audio.read_audio` hands it to ffmpeg."""


class SilentAudioError(FileProblem):
    """The audio holds no signal (all samples at or near zero)."""


class WrongSampleRateError(FileProblem):
    """The audio's sample rate is not one the reader accepts or not the one declared."""


class NotVideoError(FileProblem):
    """The file is not a readable video (no video stream, unknown format)."""


class MissingDependencyError(AssetsError):
    """An optional dependency (e.g. mediapipe for video) or tool (ffmpeg) is not installed."""


class TruncatedFileError(FileProblem):
    """The file ends early: a truncated WAV or video, or fewer rows/frames than declared."""


class GridNotFoundError(FileProblem):
    """The folder given as the GRID s1 corpus holds none of its sentences (a ``video/*.mp4`` with its
    ``align/*.align``): missing, mistyped, or the shared data not where the default looks."""


class CorpusFormatError(FileProblem):
    """A track or corpus file (manifest, params.csv, phonemes.json) does not follow its layout."""


class MeshError(AssetsError, ValueError):
    """A head mesh cannot be read or cannot be rigged (no faces, degenerate, ...)."""


class LandmarkError(AssetsError, ValueError):
    """A landmarks JSON file is unreadable, incomplete or inconsistent with its mesh."""


class RigFileError(AssetsError, ValueError):
    """A rig .npz file is unreadable, of another version, or has inconsistent arrays."""


class AssetError(AssetsError, RuntimeError):
    """The built-in head's assets could not be fetched or read."""


class GlbError(AssetsError, ValueError):
    """A head or animation cannot be written as glTF (bad shapes, unknown image type)."""


class RigCheckError(AssetsError, ValueError):
    """A rig fails the extreme-pose checks (flipped triangles, stretch, lips, teeth)."""


class AlignmentFormatError(FileProblem):
    """A phone-alignment file (.lab, TextGrid, phone JSON) cannot be parsed."""


class SynthesisError(AssetsError):
    """espeak-ng failed: library missing, unknown voice, or synthesis error."""
