"""Shared pieces of the server benchmarks: the model to serve, a server in its own process, the
real-time ingest and recording viewers.

The server runs as ``facecast serve`` in a child process so clients and server have their own
event loops (and their own GIL), as in production; the clients measure with ``time.time()``,
the same wall clock the server stamps its send times with.
"""

from __future__ import annotations

import asyncio
import contextlib
import re
import shutil
import struct
import subprocess
import sys
import tempfile
import threading
import time
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from realtime_core.avmodel import AvModel
from wire import protocol as P


def benchmark_model(path: Path | str | None) -> tuple[AvModel, Path, str]:
    """(model, its file, description): ``path``, else the shipped default model, else a random
    model of the paper's size (28 states x 5 mixtures, 11 cepstra, tc = 3: the same per-frame cost)."""
    from assets.modelfile import DEFAULT_MODEL, load_model, resolve_model, save_model

    if path is not None:  # a file or a shipped name (assets.modelfile.resolve_model)
        return load_model(path), resolve_model(path), str(path)
    if DEFAULT_MODEL.is_file():
        return load_model(None), DEFAULT_MODEL, "shipped default model"
    from realtime_core.features import FrontEndConfig, MfccConfig
    from realtime_core.hmm.sampling import random_av_hmm

    fe = FrontEndConfig(mfcc=MfccConfig(sample_rate_hz=16000, n_ceps=11), tc=3)
    hmm = random_av_hmm(np.random.default_rng(0), n_states=28, n_mix=5, n_audio=fe.audio_dim, n_visual=4)
    model = AvModel(hmm=hmm, frontend=fe, cmvn_mean=np.zeros(11), cmvn_var=np.ones(11), metadata={"recipe": "bench"})
    out = Path(tempfile.mkdtemp(prefix="fcbench")) / "paper_size_random.npz"
    save_model(out, model)
    return model, out, "random model of the paper's size (28 states x 5 mixtures, 77-dim audio; no default model yet)"


class ServerProcess:
    """``facecast serve`` in a child process on a free port; ``url`` once started; ``stop()`` sends SIGTERM.
    args: more command-line options (e.g. ``("--text",)``)."""

    def __init__(
        self, model_path: Path, *, head: bool = True, config_toml: str | None = None, args: tuple[str, ...] = ()
    ) -> None:
        cmd = [str(Path(sys.executable).parent / "facecast"), "serve", "--port", "0", "--model", str(model_path)]
        if not head:
            cmd.append("--no-head")
        cmd += args
        self._config_dir: Path | None = None
        """The temporary folder of ``config_toml``'s file, removed by ``stop()``."""
        if config_toml:
            self._config_dir = Path(tempfile.mkdtemp(prefix="fcbench"))
            cfg = self._config_dir / "server.toml"
            cfg.write_text(config_toml)
            cmd += ["--config", str(cfg)]
        self.proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        assert self.proc.stdout is not None and self.proc.stderr is not None  # both are PIPEs
        self.url = ""
        self.log_tail: deque[str] = deque(maxlen=200)
        """The server's last output lines (stdout and stderr), for a report when it fails."""
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:
            line = self.proc.stdout.readline()
            if not line:
                raise RuntimeError(f"server exited: {self.proc.stderr.read()[-2000:]}")
            m = re.search(r"listening on (http://\S+)", line)
            if m:
                self.url = m.group(1)
                # Drain both pipes for the rest of the run: a full pipe (64 KB of log) would block the
                # server's next write and stall its event loop (connections then die of ping timeouts).
                for pipe in (self.proc.stdout, self.proc.stderr):
                    threading.Thread(target=self._drain, args=(pipe,), daemon=True).start()
                return
        raise RuntimeError("server did not start within 120 s")

    def _drain(self, pipe) -> None:
        for line in pipe:
            self.log_tail.append(line)

    def cpu_by_process(self, *, tree: bool = True) -> dict[int, float]:
        """{pid: user + system CPU seconds so far, from /proc} of the server process and, with ``tree``,
        its live descendants (the workers of ``--workers``)."""
        import os

        pids = [self.proc.pid]
        if tree:
            i = 0
            while i < len(pids):  # breadth-first over /proc/<pid>/task/<tid>/children
                with contextlib.suppress(OSError):
                    for task in Path(f"/proc/{pids[i]}/task").iterdir():
                        pids += [int(c) for c in (task / "children").read_text().split()]
                i += 1
        out = {}
        for pid in pids:
            with contextlib.suppress(OSError):  # a child that just exited
                fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
                out[pid] = (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
        return out

    def stop(self) -> int:
        try:
            if self.proc.poll() is None:
                self.proc.terminate()
                try:
                    return self.proc.wait(timeout=20)
                except subprocess.TimeoutExpired:
                    self.proc.kill()
            return self.proc.wait()
        finally:
            if self._config_dir is not None:
                shutil.rmtree(self._config_dir, ignore_errors=True)


@dataclass
class FrameLog:
    """Per received frame: index, receipt time and the server's send time (s, wall clock)."""

    index: list[int] = field(default_factory=list)
    received: list[float] = field(default_factory=list)
    sent: list[float] = field(default_factory=list)
    close_code: int | None = None


_HDR = struct.Struct("<BBBxIIfdd")


async def record_viewer(
    url: str, session: str, *, kind: str = "params", encoding: str | None = None, audio: bool = False, log: FrameLog
) -> FrameLog:
    """A lean viewer: parses only the header of each frame (what a benchmark needs)."""
    from urllib.parse import urlencode

    from websockets.asyncio.client import connect
    from websockets.exceptions import ConnectionClosed

    from clients.client import ws_url

    q = {"session": session, "kind": kind, "audio": "1" if audio else "0"}
    if encoding:
        q["encoding"] = encoding
    async with connect(ws_url(url, "/view?" + urlencode(q)), compression=None, max_size=None) as ws:
        await ws.recv()  # description
        try:
            while True:
                data = await ws.recv()
                assert isinstance(data, bytes), "the view stream sends binary frames after its description"
                now = time.time()
                _, k, _, index, _, _, _, sent = _HDR.unpack_from(data)
                if k != P.KIND_AUDIO:
                    log.index.append(index)
                    log.received.append(now)
                    log.sent.append(sent)
        except ConnectionClosed as exc:
            log.close_code = exc.rcvd.code if exc.rcvd else None
    return log


async def wait_for_session(url: str, name: str, timeout_s: float = 10.0) -> None:
    import json

    from clients.client import http_get

    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        _, body = await http_get(url, "/metrics")
        if any(s["name"] == name for s in json.loads(body)["session_list"]):
            return
        await asyncio.sleep(0.02)
    raise RuntimeError(f"session {name} did not appear")


def speech_signal(seconds: float, rate_hz: int = 16000, seed: int = 0) -> np.ndarray:
    """(n,) int16 speech-like test audio (voiced harmonics with a syllable envelope, noise bursts)."""
    rng = np.random.default_rng(seed)
    n = int(seconds * rate_hz)
    t = np.arange(n) / rate_hz
    phase = 2 * np.pi * np.cumsum(120 + 30 * np.sin(2 * np.pi * 0.7 * t)) / rate_hz
    voiced = sum(np.sin(h * phase) / h for h in range(1, 12))
    env = np.clip(np.sin(2 * np.pi * 3.1 * t + seed), 0, None) ** 1.5
    x = 0.25 * env * voiced + 0.05 * rng.standard_normal(n) * (np.sin(2 * np.pi * 1.3 * t) > 0.6)
    return np.rint(x / np.abs(x).max() * 0.8 * 32767).astype(np.int16)
