"""The one exception root of facecast (:class:`FacecastError`), the shared :class:`ConfigError`,
and the errors of :mod:`realtime_core`.

Every package's family hangs under :class:`FacecastError` (``RealtimeCoreError`` here,
``assets.errors.AssetsError``, ``server.errors.ServerError``, ``clients.errors.ClientError``,
``training.errors.TrainingError``), so the command line catches one type and prints one line.
It lives in the lowest layer because every other package may import it.

Every problem realtime_core detects in its input raises a subclass of
:class:`RealtimeCoreError` whose message names the problem (and the offending value
or array), so callers at the I/O edge can catch one type and report it.
"""

from __future__ import annotations


class FacecastError(Exception):
    """Root of every error facecast raises on purpose (bad input, bad configuration, bad files)."""


class ConfigError(FacecastError, ValueError):
    """A configuration value is out of range or inconsistent (any package's frozen config)."""


class RealtimeCoreError(FacecastError):
    """Root of every error raised by realtime_core on bad input (configuration errors are
    :class:`ConfigError`, shared by every package)."""


class InvalidAudioError(RealtimeCoreError, ValueError):
    """Audio samples have the wrong dtype/shape, contain NaN/inf, or are too short."""


class NotSpeechError(InvalidAudioError):
    """Valid audio that does not sound like speech (a tone, noise or music), where speech is needed: an enrolment
    (:data:`realtime_core.adaptation.MIN_VISITED_SHARE`)."""


class InvalidFeaturesError(RealtimeCoreError, ValueError):
    """A feature array has the wrong shape or non-finite values."""


class ModelFormatError(RealtimeCoreError, ValueError):
    """A model's arrays have wrong shapes, non-finite values or non-PD covariances."""


class StreamStateError(RealtimeCoreError, RuntimeError):
    """A streaming stage was used after flush() or otherwise out of order."""
