"""The one exception root of :mod:`server`; the CLI prints these as one line."""

from __future__ import annotations

from realtime_core.errors import ConfigError, FacecastError


class ServerError(FacecastError):
    """Root of every error raised by the server package."""


class ServerConfigError(ServerError, ConfigError):
    """A server, session or source configuration value is invalid (the message names it)."""


class ProtocolViolation(ServerError):
    """A peer broke the wire protocol: close that one connection with ``code`` and ``reason``.

    code: WebSocket close code (see :mod:`wire.protocol`); reason: short text (<= 123 bytes
    UTF-8, the limit of a close frame).
    """

    def __init__(self, code: int, reason: str) -> None:
        super().__init__(f"{code}: {reason}")
        self.code = code
        self.reason = reason


class AudioFormatError(ServerError, ValueError):
    """A block of audio cannot be used: partial samples, NaN/inf or out-of-range floats, wrong shape."""


class ControlError(ServerError, ValueError):
    """A control message names an unknown control or gives an invalid value (the session goes on)."""


class AudioSourceError(ServerError, RuntimeError):
    """An audio source cannot run: no PortAudio, no input device, unreadable file."""


class IngestOverrun(ServerError):
    """An ingest ran ahead of real time beyond its burst on a server that closes instead of pacing."""
