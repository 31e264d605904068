"""The one exception root of :mod:`server`; the CLI prints these as one line."""

from __future__ import annotations

from decimal import Decimal

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


class ServerSideClose(ProtocolViolation):
    """A connection closed for the server's own reason, not the peer's fault: a viewer held for a session that
    opened in a connection worker told to connect again (4004, the hand-off to that worker), held viewers of a
    server stopping (1001). Closed with its code and reason as any violation, not logged as a client error."""


class AudioFormatError(ServerError, ValueError):
    """A block of audio cannot be used: partial samples, NaN/inf or out-of-range floats, wrong shape."""


class ControlError(ServerError, ValueError):
    """A control message names an unknown control or gives an invalid value (the session goes on)."""


class AudioSourceError(ServerError, RuntimeError):
    """An audio source cannot run: no PortAudio, no input device, unreadable file."""


class IngestOverrun(ServerError):
    """An ingest ran ahead of real time beyond its burst on a server that closes instead of pacing."""


def reason_value(value: object, limit: int = 40) -> str:
    """A client-supplied value as quoted in a reason: a number in ``%.6g`` form (``at: 1e300`` was quoted
    with 300 digits, a 400-digit JSON integer with all of them), anything else its repr cut to ``limit``
    characters, so a reason stays short (and within a close frame)."""
    if isinstance(value, int) and not isinstance(value, bool) and abs(value) < 10**15:
        return str(value)  # exact
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        try:
            return f"{float(value):.6g}"
        except OverflowError:  # an integer beyond a float's range
            return f"{Decimal(value):.6g}"
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."
