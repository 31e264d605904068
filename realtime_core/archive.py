"""Facecast's ``.npz`` archives as bytes (every model, mapper and corpus file's container; no pickle).

Apart from :mod:`realtime_core.avmodel`, whose import pulls in the HMM, the front end and scipy: a corpus
load (``facecast say``) needs only these and paid ~90 ms for that import.
"""

from __future__ import annotations

import io
import zipfile

import numpy as np

from realtime_core.errors import ModelFormatError

AVMODEL_FORMAT = "facecast-avmodel"
"""``format`` of an HMM model file (:mod:`realtime_core.avmodel`)."""
MLP_MAPPER_FORMAT = "facecast-mlpmapper"
"""``format`` of an MLP mapper file (:mod:`realtime_core.mapping.model`). Both names live here so that each
reader can tell a file of the other kind by name ("use --mapper mlp") without importing the other."""


def npz_bytes(arrays: dict[str, np.ndarray]) -> bytes:
    """``.npz`` archive bytes of named arrays (no pickle): the container of every model file."""
    buf = io.BytesIO()
    np.savez(buf, **arrays)  # type: ignore[arg-type]  # numpy stubs type **kwds as allow_pickle
    return buf.getvalue()


NOT_NPZ = "not an .npz file (no zip header)"
"""Why bytes that do not start as a zip archive are refused. numpy takes any such file for a pickle and
says to load it unsafely with ``allow_pickle``: advice a user must not be given."""


def require_npz(data: bytes, what: str) -> None:
    """:class:`ModelFormatError` naming ``what`` unless ``data`` starts as a zip archive (an ``.npz``)."""
    if not data.startswith(b"PK"):
        raise ModelFormatError(f"not a facecast {what} archive: {NOT_NPZ}")


def npz_arrays(data: bytes, what: str) -> dict[str, np.ndarray]:
    """The named arrays of ``.npz`` bytes (pickle refused); :class:`ModelFormatError` if it is not one."""
    require_npz(data, what)
    try:
        npz = np.load(io.BytesIO(data), allow_pickle=False)
        return {k: npz[k] for k in npz.files}
    except (ValueError, OSError, zipfile.BadZipFile, EOFError) as exc:
        raise ModelFormatError(f"not a facecast {what} archive ({exc})") from None
