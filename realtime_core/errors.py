"""The one exception root of :mod:`realtime_core` and its specific subclasses.

Every problem realtime_core detects in its input raises a subclass of
:class:`RealtimeCoreError` whose message names the problem (and the offending value
or array), so callers at the I/O edge can catch one type and report it.
"""

from __future__ import annotations


class RealtimeCoreError(Exception):
    """Root of every error raised by realtime_core."""


class ConfigError(RealtimeCoreError, ValueError):
    """A configuration value is out of range or inconsistent."""


class InvalidAudioError(RealtimeCoreError, ValueError):
    """Audio samples have the wrong dtype/shape, contain NaN/inf, or are too short."""


class InvalidFeaturesError(RealtimeCoreError, ValueError):
    """A feature array has the wrong shape or non-finite values."""


class ModelFormatError(RealtimeCoreError, ValueError):
    """A model's arrays have wrong shapes, non-finite values or non-PD covariances."""


class StreamStateError(RealtimeCoreError, RuntimeError):
    """A streaming stage was used after flush() or otherwise out of order."""
