"""Where the project's shared data lives (``../shared/data`` beside the checkout: heads, speech, the GRID
corpora), read in place and never copied into the repository.

One rule for every command, benchmark, script and test: ``$FACECAST_SHARED_DATA`` when it is set (a git
worktree elsewhere, a CI layout), else ``shared/data`` in the folder that holds the checkout.
"""

from __future__ import annotations

import os
from pathlib import Path

ENV = "FACECAST_SHARED_DATA"
"""The environment variable that overrides the default place."""


def shared_data_root() -> Path:
    """The shared data folder: ``$FACECAST_SHARED_DATA`` if set (and not empty), else ``../shared/data`` beside
    the repository checkout. Not checked for existence: each reader names the file it misses."""
    shared = os.environ.get(ENV)
    return Path(shared) if shared else Path(__file__).resolve().parents[2] / "shared" / "data"
