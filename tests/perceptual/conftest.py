"""Fixtures of the perceptual-experiment tests: a tiny real stimulus set, built once and cached under
artifacts/ (helpers in :mod:`tests.perceptual.harness`)."""

from __future__ import annotations

import pytest

from tests.perceptual.harness import ARTIFACTS, grid_root, tiny_config
from tests.prerequisites import require


@pytest.fixture(autouse=True)
def _node_tmpdir(tmp_path_factory: pytest.TempPathFactory, monkeypatch: pytest.MonkeyPatch) -> None:
    """The browser check's node process (and its Chromium profile) uses the test's own temporary folder
    (as in tests/clients/web/conftest.py: a profile Chromium writes into after it closed stays there)."""
    monkeypatch.setenv("TMPDIR", str(tmp_path_factory.mktemp("node-tmp")))


@pytest.fixture(scope="session")
def stimuli():
    import shutil

    root = grid_root()
    require(root is not None, "GRID s1 corpus not found in ../shared/data/video/grid_s1")
    require(shutil.which("ffmpeg") is not None, "ffmpeg is not installed")
    import fcntl

    from perceptual.stimuli import build

    # `./go test` runs test files in parallel processes (pytest-xdist): the four files that use the stimuli may
    # land in two, each with this session fixture. One builds while the other waits on the lock, then reuses what
    # was built (build() reuses finished stimuli); never two processes writing the same files.
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    with open(ARTIFACTS / "stimuli.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        return build(tiny_config(ARTIFACTS / "stimuli", root))
