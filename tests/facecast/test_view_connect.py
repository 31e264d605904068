"""``facecast view --record`` on a server that is not there: one line naming the URL, exit 2 (was a
ConnectionRefusedError traceback from fetching the head)."""

from __future__ import annotations

import socket

from facecast.cli import main


def test_view_record_on_a_closed_port_says_it_cannot_connect(tmp_path, capsys):
    with socket.socket() as s:  # a port that was free a moment ago: nothing listens on it
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    url = f"http://127.0.0.1:{port}"
    assert main(["view", url, "--session", "s", "--record", str(tmp_path / "take.mp4")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and f"{url}: cannot connect" in err, err
    assert list(tmp_path.iterdir()) == []
