"""Errors of :mod:`clients.export` (under the package root :class:`clients.errors.ClientError`)."""

from __future__ import annotations

from clients.errors import ClientError


class ExportError(ClientError, ValueError):
    """A track, head or output path cannot be exported (bad shape, unknown suffix, unreadable file)."""
