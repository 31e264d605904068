"""The file-system edge shared by every package: atomic writes.

Everything facecast writes (corpora, models, rigs, caches, exports) goes through
:func:`atomic_write_bytes`, so a reader sees the old file or the new one, never half of one,
and an interrupted run leaves no partial file under the final name.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path``: a temporary file in the same folder, then ``os.replace``.

    The file gets mode 0644 (mkstemp's 0600 would hide shared caches and models from others).
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path
