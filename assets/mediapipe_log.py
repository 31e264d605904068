"""MediaPipe's native (C++) logging kept off stderr, for the two places that run its face mesh in a
user's process: the face tracker of ``facecast extract``/``eval`` (:mod:`training.video`) and the
automatic landmarks (:mod:`clients.render.landmarks`). Its absl logging ignores GLOG_minloglevel and
writes notices ("inference_feedback_manager ... Feedback manager requires a model ...") from the
graph's threads while a graph starts, so only the file descriptor itself can be silenced."""

from __future__ import annotations

import contextlib
import os
import sys
from collections.abc import Iterator


@contextlib.contextmanager
def native_stderr_quiet() -> Iterator[None]:
    """File descriptor 2 to /dev/null for the block. Python exceptions still propagate (printed after
    the block, by whoever handles them); only the descriptor is swapped, and restored on exit."""
    sys.stderr.flush()
    saved = os.dup(2)
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 2)
        yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)
        os.close(devnull)
