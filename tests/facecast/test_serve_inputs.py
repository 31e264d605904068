"""``facecast serve --file`` with a file it cannot read fails before it listens (as --mic does)."""

from __future__ import annotations

import pytest

from facecast.cli import main


def test_a_bad_file_source_fails_before_listening(tmp_path, capsys):
    from assets.modelfile import save_model
    from tests.speech import small_model

    model = save_model(tmp_path / "m.npz", small_model())
    notes = tmp_path / "notes.wav"
    notes.write_text("not audio")
    for bad, problem in ((tmp_path / "missing.wav", "file not found"), (notes, "not audio")):
        assert main(["serve", "--port", "0", "--no-head", "--model", str(model), "--file", str(bad)]) == 2
        out, err = capsys.readouterr()
        assert "listening" not in out, out
        assert len(err.strip().splitlines()) == 1 and f"{bad}: {problem}" in err, err


def test_the_start_line_names_the_mlp_mapper(tmp_path, capsys):
    # `facecast serve --mapper mlp` announced "model default" (the HMM's name) for the MLP mapper it served.
    notes = tmp_path / "notes.wav"
    notes.write_text("not audio")
    assert main(["serve", "--port", "0", "--no-head", "--mapper", "mlp", "--file", str(notes)]) == 2
    out = capsys.readouterr().out
    assert "facecast serve: MLP mapper default, algorithmic delay" in out, out


def test_a_mesh_head_is_announced_before_it_is_rigged(tmp_path, capsys):
    """`serve --head SCAN.glb` printed its model line, then nothing for the minutes its first rig took."""
    from assets.modelfile import save_model
    from tests.speech import small_model

    model = save_model(tmp_path / "m.npz", small_model())
    empty = tmp_path / "empty.obj"
    empty.write_text("v 0 0 0\nv 1 0 0\n")  # fails while it is being rigged: after the announcement
    assert main(["serve", "--port", "0", "--model", str(model), "--head", str(empty)]) == 2
    out, err = capsys.readouterr()
    assert f"facecast serve: head {empty}: loading; a mesh with enough mouth targets is driven by them" in out, out
    assert "ready" not in out, out
    assert len(err.strip().splitlines()) == 1 and "empty.obj" in err, err


def test_a_wrong_redis_address_fails_before_the_model_loads(tmp_path, capsys):
    """`serve --redis redis://127.0.0.1:PORT` with nothing there said so only once the server started, after its
    model and head had loaded (13.8 s). It is asked first: one line naming the address, exit 2, nothing loaded (the
    model named here does not even exist: its error would come first otherwise)."""
    import socket

    with socket.socket() as held:  # bound, never listening: a connection to it is refused
        held.bind(("127.0.0.1", 0))
        url = f"redis://127.0.0.1:{held.getsockname()[1]}/0"
        missing = tmp_path / "missing.npz"
        assert main(["serve", "--port", "0", "--no-head", "--model", str(missing), "--redis", url]) == 2
    out, err = capsys.readouterr()
    assert "facecast serve: model" not in out and "listening" not in out, out
    lines = err.strip().splitlines()
    assert len(lines) == 1 and f"cannot reach Redis at {url}: " in lines[0] and "refused" in lines[0], err


@pytest.mark.system  # `facecast serve` in its own process, asked over loopback
@pytest.mark.parametrize("allowed", [["localhost"], ["face.example.org", "10.0.0.11"]], ids=["loopback-name", "none"])
def test_the_listening_line_gives_a_url_the_host_check_accepts(tmp_path, allowed):
    """`serve` printed "listening on http://127.0.0.1:PORT" with allowed_hosts set, and every request to that URL
    was refused (403 Host not allowed; docs/deploy.md's node config copied as printed). Now the URL printed answers;
    when allowed_hosts admits no address of this server, the line names those hosts and prints no URL."""
    import re
    import subprocess
    import sys
    import urllib.request
    from pathlib import Path

    from assets.modelfile import save_model
    from tests.speech import small_model

    model = save_model(tmp_path / "m.npz", small_model())
    cfg = tmp_path / "server.toml"
    cfg.write_text(f"[server]\nallowed_hosts = {allowed!r}\n".replace("'", '"'))
    cmd = [sys.executable, "-m", "facecast", "serve", "--port", "0", "--no-head", "--model", str(model)]
    repo = Path(__file__).resolve().parents[2]  # this checkout's code (the venv's `facecast` may be another's)
    proc = subprocess.Popen(
        [*cmd, "--config", str(cfg)], cwd=repo, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True
    )
    try:
        assert proc.stdout is not None
        line = ""
        while "listening on" not in line:
            line = proc.stdout.readline()
            assert line, "the server exited before listening"
        urls = re.findall(r"listening on (http://\S+)", line)
        if allowed == ["localhost"]:
            assert urls and urls[0].startswith("http://localhost:"), line
            with urllib.request.urlopen(urls[0] + "/health", timeout=10) as reply:
                assert reply.status == 200
        else:
            assert not urls and "allowed_hosts admits only face.example.org, 10.0.0.11" in line, line
            port = int(re.search(r"port (\d+)", line).group(1))
            with pytest.raises(urllib.error.HTTPError) as refused:  # as the line says
                urllib.request.urlopen(f"http://127.0.0.1:{port}/health", timeout=10)
            assert refused.value.code == 403
    finally:
        proc.terminate()
        proc.wait(timeout=30)
