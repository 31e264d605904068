"""The server hands the browser viewer its page, its modules and three.js, and nothing else."""

from __future__ import annotations

import pytest

from clients.client import http_get
from tests.live_server import REPO
from tests.prerequisites import missing

# A live server over loopback.
pytestmark = pytest.mark.system


def test_viewer_page_modules_and_vendor_files(live):
    get = lambda path: live.call(http_get(live.url, path))
    status, body = get("/")
    assert status == 200 and b'<script type="importmap">' in body and b"/vendor/three/build/three.module.js" in body
    for path in ("/js/main.js", "/js/protocol.js", "/js/playout.js", "/js/head.js", "/style.css"):
        assert get(path)[0] == 200, path
    if not (REPO / "node_modules" / "three").is_dir():
        missing("node_modules/three is missing (scripts/setup.sh runs `npm ci`)")
    status, body = get("/vendor/three/build/three.module.js")
    assert status == 200 and b"REVISION" in body
    assert get("/vendor/three/examples/jsm/controls/OrbitControls.js")[0] == 200
    # Only three's build/ and examples/jsm/ are public: not its package.json, other packages or ../
    for path in (
        "/vendor/three/package.json",
        "/vendor/playwright-core/package.json",
        "/vendor/three/build/../package.json",
        "/vendor/three/build/%2e%2e/package.json",
        "/../pyproject.toml",
        "/vendor/three/examples/jsm/../../../../pyproject.toml",
    ):
        assert get(path)[0] == 404, path
