"""The one exception root of :mod:`clients`; every subclass message names the file and the problem."""

from __future__ import annotations

from realtime_core.errors import FacecastError


class ClientError(FacecastError):
    """Root of every error raised by clients (viewers, renderer, exporters, client tools)."""


class RenderError(ClientError, RuntimeError):
    """Rendering or video muxing failed (no EGL context, ffmpeg error, bad parameters file)."""
