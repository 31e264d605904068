"""Cache directory and atomic file writes."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np

from clients.errors import AssetError


def cache_dir() -> Path:
    """``$FACECAST_CACHE`` or ``~/.cache/facecast`` (created on demand)."""
    root = os.environ.get("FACECAST_CACHE")
    p = Path(root).expanduser() if root else Path.home() / ".cache" / "facecast"
    try:
        p.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise AssetError(f"{p}: cannot create the cache directory (set FACECAST_CACHE): {exc}") from exc
    return p


def atomic_savez(path: str | os.PathLike, **arrays: np.ndarray) -> Path:
    """``np.savez`` to a temp file in the same directory, then ``os.replace`` (readers never see half a file)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp.npz", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            np.savez(f, **arrays)
        os.chmod(tmp, 0o644)  # mkstemp makes 0600; caches are shared read-only data
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return path
