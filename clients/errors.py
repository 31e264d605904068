"""The one exception root of :mod:`clients`; every subclass message names the file and the problem."""

from __future__ import annotations


class ClientError(Exception):
    """Root of every error raised by clients."""


class MeshError(ClientError, ValueError):
    """A head mesh cannot be read or cannot be rigged (no faces, degenerate, ...)."""


class LandmarkError(ClientError, ValueError):
    """A landmarks JSON file is unreadable, incomplete or inconsistent with its mesh."""


class RigFileError(ClientError, ValueError):
    """A rig .npz file is unreadable, of another version, or has inconsistent arrays."""


class AssetError(ClientError, RuntimeError):
    """The built-in head's assets could not be fetched or read."""


class RenderError(ClientError, RuntimeError):
    """Rendering or video muxing failed (no EGL context, ffmpeg error, bad parameters file)."""
