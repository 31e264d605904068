"""Cache directory and atomic file writes."""

from __future__ import annotations

import io
import os
from pathlib import Path

import numpy as np

from assets.errors import AssetError
from assets.files import atomic_write_bytes


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
    """``np.savez`` written atomically (see :func:`assets.files.atomic_write_bytes`)."""
    buf = io.BytesIO()
    # numpy's stub types **kwds against savez's own allow_pickle: bool, so any **dict of arrays is rejected
    np.savez(buf, **arrays)  # type: ignore[arg-type]
    return atomic_write_bytes(path, buf.getvalue())
