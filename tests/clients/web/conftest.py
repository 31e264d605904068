"""The browser checks' node processes get the test's own temporary folder as TMPDIR.

Their Chromium profile is made there (harness.mjs: ``mkdtemp(os.tmpdir())``). The scripts remove it when
they end, but Chromium's helper processes can still write into it after the browser is closed, so a
profile sometimes came back in /tmp after every run (three of six checks, 2 MB each); under the test's
temporary folder pytest's own rotation removes whatever is left.
"""

from __future__ import annotations

import pytest


@pytest.fixture(autouse=True)
def _node_tmpdir(tmp_path_factory: pytest.TempPathFactory, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("TMPDIR", str(tmp_path_factory.mktemp("node-tmp")))
