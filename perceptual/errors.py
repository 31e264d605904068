"""Errors of the perceptual test kit; every message names the file (or participant) and the problem."""

from __future__ import annotations

from clients.errors import ClientError


class PerceptualError(ClientError):
    """Root of the perceptual kit's errors."""


class BuildError(PerceptualError, RuntimeError):
    """Stimuli cannot be built (missing corpus, too few sentences, synthesis or ffmpeg failure)."""


class ManifestError(PerceptualError, ValueError):
    """A stimulus manifest is missing, of another version, tampered with (hash mismatch) or stale."""


class StoreError(PerceptualError, ValueError):
    """A response database is unreadable, of another schema version, or belongs to another test."""


class AnswerError(PerceptualError, ValueError):
    """A submitted answer does not fit the participant's plan (unknown trial, wrong stimulus, bad response)."""
