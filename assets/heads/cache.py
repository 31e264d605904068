"""Cache directory and atomic file writes; stale generations of a cache file removed."""

from __future__ import annotations

import io
import os
import re
import time
from collections.abc import Callable
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


# A sibling written within this long may be another checkout's current file: checkouts at different rig
# algorithms share one cache (benchmarks alternate a parent commit and its child on the same cache), and
# removing it at once would have each rebuild the other's file on every run.
STALE_AFTER_S = 24 * 3600.0


def remove_stale_siblings(
    path: Path,
    family: re.Pattern[str],
    *,
    now: float | None = None,
    stale: Callable[[Path], bool] | None = None,
) -> list[Path]:
    """After ``path`` (a cache file of ``family``, a pattern its name fully matches) was written: remove
    the other files in its folder whose names fully match ``family`` and that were last written over
    :data:`STALE_AFTER_S` ago (each rig algorithm or key change leaves one, 0.7 MB or more) and, if
    ``stale`` is given, for which it is true (a family whose names do not tell the current file from
    an older generation's). Other files are never touched; a file that cannot be removed (read-only
    cache, removed meanwhile) is skipped. Returns the removed paths."""
    now = time.time() if now is None else now
    removed = []
    for p in path.parent.iterdir():
        if p.name == path.name or not family.fullmatch(p.name):
            continue
        try:
            if now - p.stat().st_mtime > STALE_AFTER_S and (stale is None or stale(p)):
                p.unlink()
                removed.append(p)
        except OSError:  # read-only cache, a folder of that name, another process removed it: kept
            continue
    return removed
