"""`facecast warm-up` (run by scripts/setup.sh): afterwards the commands a new user runs first compile
no numba kernel, they only load them.

numba's debug output names every kernel it compiles and saves ("data saved to") or loads ("data
loaded from"); each process here gets a fresh cache directory of its own (NUMBA_CACHE_DIR), so the
repository's cache is neither used nor touched."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import pytest

from tests.prerequisites import require_tool

# Compiles every kernel (~20 s of CPU); espeak-ng and the built-in head (its first use downloads it).
pytestmark = [pytest.mark.slow, pytest.mark.system]

# say (unit selection, the built-in head's morph rig and glTF export), animate (the live path, as
# render runs it) and a server session's warm-up with the built-in head (the keyframe solve per frame).
FIRST_COMMANDS = """
import sys
from facecast.cli import main
out = sys.argv[1]
assert main(["say", "bin blue at f two now", "-o", out + "/s.glb", "-o", out + "/s.wav"]) == 0
assert main(["animate", out + "/s.wav", "--csv", out + "/s.csv"]) == 0
from assets.heads.head import resolve_head
from assets.modelfile import load_speech_model
from server.session import warm_up
warm_up(load_speech_model(), resolve_head("builtin").rig)
"""


def _run(args: list[str], env: dict[str, str]) -> str:
    r = subprocess.run([sys.executable, *args], env=env, capture_output=True, text=True, timeout=1800)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    return r.stdout


def test_after_warm_up_the_first_commands_compile_no_kernel(builtin_head, tmp_path):
    require_tool("espeak-ng", "apt package espeak-ng")
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "numba"), "NUMBA_DEBUG_CACHE": "1"}
    warm = _run(["-m", "facecast", "warm-up"], env)
    assert "warm-up: numba kernels ready" in warm
    assert "warm-up: built-in head's morph rig ready" in warm  # in the facecast cache: say reads it back
    compiled = {line.split("'")[1] for line in warm.splitlines() if "data saved to" in line}
    # Every kernel module was compiled into the fresh directory (so the check below can fail).
    for module in ("features", "inversion", "face"):
        assert any(f"/{module}_" in p and "/compiled." in p for p in compiled), compiled  # numba/<dir>_<hash>/
    assert any("keyframe_weights" in p for p in compiled) and any("filter_rows" in p for p in compiled)

    first = _run(["-c", textwrap.dedent(FIRST_COMMANDS), str(tmp_path)], env)
    assert "data loaded from" in first  # the kernels came from the cache the warm-up filled
    saved = [line for line in first.splitlines() if "data saved to" in line]
    assert not saved, "compiled after the warm-up:\n" + "\n".join(saved)
