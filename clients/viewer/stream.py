"""A viewer connection that collects one session: its description, frames and relayed audio.

Frames and audio carry media times (seconds of the session's audio), so a recording is laid on one
timeline: video frame i is session frame ``first + i`` (a frame the server dropped is replaced by
the one before it, so the timeline never shifts) and the audio starts at the first frame's media
time. Vertex deltas are kept as float16 (27 kB per frame for the built-in head: about 50 MB per
minute; the wire's int16 already limits them to 1/32767 of the frame's peak), the few values of
parameters and blendshapes as the float32 the wire carries, so exports equal the session exactly.
"""

from __future__ import annotations

import asyncio
import json
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from urllib.parse import quote

import numpy as np

from assets.heads.mesh import HeadMesh
from clients.client import ServerClosed, ViewerClient, http_get
from clients.errors import ClientError
from wire import protocol as P

RETRY_S = 0.05
"""Wait between attempts to watch a session that has not started (4004) or to find one. A viewer asks the server
to hold it until the session starts (the view query's ``wait``, docs/protocol.md section 3), so against this
project's server it connects once and gets the session from its first audio block; the retries are for a server
that holds no viewers (an older one: it answers 4004 at once) and for a hold the server ended before ``wait_s``
(its ``max_view_wait_s``; a session that started in another worker process). Against a server that holds no
viewers a session's first frame leaves about 0.2 s after its audio starts and nothing is replayed to a later
viewer: retried every 0.25 s, a recording started before the speech lost its first 3-11 frames (0.1-0.37 s).
20 attempts a second stay well inside a server's per-client connection rate (``connect_rate_per_s``, 50/s)."""


@dataclass(frozen=True, kw_only=True)
class ViewerStreamConfig:
    """url: the server (http://host:port); session: its name; kind: "params", "deltas" or
    "blendshapes"; encoding: None = the kind's default; token: the shared secret, if any;
    wait_s: how long to wait for the session to appear (0 = it must exist now); max_s: stop
    after this many seconds of frames (None = until the session ends)."""

    url: str
    session: str
    kind: str = "params"
    encoding: str | None = None
    token: str | None = None
    wait_s: float = 10.0
    max_s: float | None = None

    def __post_init__(self) -> None:
        if self.kind not in P.VIEW_KINDS:
            raise ClientError(f"kind must be one of {sorted(P.VIEW_KINDS)}, got {self.kind!r}")
        if not P.SESSION_NAME.match(self.session):
            raise ClientError(f"session name must match {P.SESSION_NAME.pattern}, got {self.session!r}")
        if not (self.wait_s >= 0):
            raise ClientError(f"wait_s must be >= 0 s, got {self.wait_s!r}")
        if self.max_s is not None and not (self.max_s > 0):
            raise ClientError(f"max_s must be > 0 s or None, got {self.max_s!r}")
        if not self.url.startswith(("http://", "https://", "ws://", "wss://")):
            raise ClientError(f"url must start with http:// or ws://, got {self.url!r}")


@dataclass
class Recording:
    """What a viewer collected. description: the server's JSON; index (F,) int64 frame indices;
    media_time (F,) s; values: F arrays (V,) per frame (V = description values_per_frame; float16
    for vertex deltas, float32 otherwise);
    audio: list of (media_time s, samples (n,) float32 in [-1, 1]); close_code/reason: how it ended
    (None / "" when the viewer stopped at its max_s: ``stopped`` is then True)."""

    description: dict
    index: list[int] = field(default_factory=list)
    media_time: list[float] = field(default_factory=list)
    values: list[np.ndarray] = field(default_factory=list)
    audio: list[tuple[float, np.ndarray]] = field(default_factory=list)
    close_code: int | None = None
    close_reason: str = ""
    stopped: bool = False

    @property
    def ending(self) -> str:
        """How the recording ended, for a person: the server's close, or the viewer's own stop (a
        --duration run printed "session closed with None" while the session went on)."""
        if self.stopped:
            return f"stopped after {len(self.index) / self.fps:.2f} s of frames (the session goes on)"
        if self.close_code is None:  # no close frame: it read "session closed with None" after a kill -9
            return f"lost the server: {self.close_reason}".rstrip(": ")
        return f"session closed with {self.close_code} {self.close_reason}".rstrip()

    @property
    def partial(self) -> bool:
        """True when the session was closed other than by its end (1001 server shutting down, 4000 too slow, the
        server lost): what arrived is a part of the take (a --duration stop is a whole one)."""
        return not self.stopped and self.close_code != P.CLOSE_NORMAL

    @property
    def fps(self) -> float:
        return float(self.description["fps"])

    @property
    def audio_rate_hz(self) -> int:
        a = self.description.get("audio") or {}
        return int(a.get("rate_hz", 16000))

    def timeline(self) -> tuple[np.ndarray, int]:
        """(frames (N, V) float32, first index): one row per frame index from the first to the last
        received, gaps (dropped frames) filled with the previous frame."""
        if not self.index:
            raise ClientError("the recording has no frames")
        idx = np.asarray(self.index, dtype=np.int64)
        first = int(idx[0])
        rows = idx - first
        # For each timeline slot, the last received frame at or before it.
        slot_to_row = np.searchsorted(rows, np.arange(rows[-1] + 1), side="right") - 1
        return np.asarray(self.values, dtype=np.float32)[slot_to_row], first

    def audio_track(self, start_s: float, n_frames: int) -> np.ndarray:
        """(n,) float32 samples covering ``n_frames`` frames from media time ``start_s``: each block
        placed at its media time (silence where nothing arrived)."""
        rate = self.audio_rate_hz
        n = int(round(n_frames / self.fps * rate))
        out = np.zeros(n, dtype=np.float32)
        for t, block in self.audio:
            at = int(round((t - start_s) * rate))
            lo, hi = max(at, 0), min(at + len(block), n)
            if hi > lo:
                out[lo:hi] = block[lo - at : hi - at]
        return out


async def fetch_head(url: str, token: str | None = None, *, targets: bool = False) -> HeadMesh:
    """The served head (``/head/mesh.json`` and ``/head/texture``) as a HeadMesh (vertex order kept). targets: also
    the morph targets the head drives (``mesh.targets``: name -> (n, 3) float64, in the order of the morph kind's
    weights; None for a retargeted head, which drives none). ClientError naming the URL and the reason when the
    head cannot be fetched."""
    auth = f"?token={quote(token)}" if token else ""
    where = f"{url}/head/mesh.json"
    try:
        status, body = await http_get(url, "/head/mesh.json" + auth)
    except OSError as exc:
        raise ClientError(f"{url}: cannot connect: {exc}") from None  # as every request to a server says it
    if status != 200:
        why = {404: "the server has no head", 401: "wrong or missing token"}.get(status, "")
        raise ClientError(f"cannot fetch the server's head {where}: it answered {status} {why}".rstrip())
    try:
        m = json.loads(body)
        texture = None
        if m.get("uvs") is not None:
            t_status, t_body = await http_get(url, "/head/texture" + auth)
            texture = t_body if t_status == 200 else None
        vertices = np.asarray(m["vertices"], dtype=np.float64).reshape(-1, 3)
        return HeadMesh(
            vertices=vertices,
            triangles=np.asarray(m["triangles"], dtype=np.int64).reshape(-1, 3),
            uvs=None if m.get("uvs") is None else np.asarray(m["uvs"], dtype=np.float64).reshape(-1, 2),
            colors=None if m.get("colors") is None else np.asarray(m["colors"], dtype=np.float32).reshape(-1, 3),
            texture=texture,
            name=where,
            targets=driven_targets(m.get("morph"), len(vertices)) if targets else None,
        )
    except (ValueError, KeyError, TypeError, IndexError) as exc:
        raise ClientError(f"{where}: unreadable: {exc}") from exc
    except OSError as exc:  # the texture's request
        raise ClientError(f"cannot fetch the server's head {url}/head/texture: {exc}") from None


def driven_targets(morph: dict | None, n: int) -> dict[str, np.ndarray] | None:
    """mesh.json's ``morph`` (docs/protocol.md: the vertices any driven target moves and per target their x, y, z)
    as name -> (n, 3) float64 displacement at weight 1, in the served order; None without one (a retargeted head)."""
    if not morph:
        return None
    moved = np.asarray(morph["vertices"], dtype=np.int64)
    if len(moved) and (moved.min() < 0 or moved.max() >= n):
        raise ValueError(f"morph vertices outside the mesh's {n}")
    out = {}
    for name, flat in zip(morph["names"], morph["deltas"], strict=True):
        d = np.zeros((n, 3), dtype=np.float64)
        d[moved] = np.asarray(flat, dtype=np.float64).reshape(len(moved), 3)
        out[str(name)] = d
    return out


def backoff(longest_s: float) -> Iterator[float]:
    """Waits (s) between attempts: :data:`RETRY_S`, then each twice the last, up to ``longest_s``."""
    wait = RETRY_S
    while True:
        yield wait
        wait = min(2 * wait, longest_s)


async def connect_viewer(cfg: ViewerStreamConfig, *, waits: Iterator[float] | None = None) -> ViewerClient:
    """A connected viewer, held by the server until the session starts (up to wait_s: the view query's ``wait``).
    Refused before wait_s is over (a server that holds no viewers, or ended the hold early), it tries again: at
    once after a hold, else after :data:`RETRY_S` or each of ``waits`` (s) in turn (:func:`backoff`; the caller's
    iterator, so it can carry the back-off over several calls)."""
    deadline = time.monotonic() + cfg.wait_s
    while True:
        asked = time.monotonic()
        v = ViewerClient(
            cfg.url,
            session=cfg.session,
            kind=cfg.kind,
            encoding=cfg.encoding,
            audio=True,
            token=cfg.token,
            wait_s=max(0.0, deadline - asked),
        )
        try:
            await v.__aenter__()
            return v
        except ServerClosed as exc:
            if exc.code != P.CLOSE_NOT_FOUND or time.monotonic() >= deadline:
                # what a user waiting for the session needs to hear: it did not start while we waited
                why = (
                    f"{exc.code} no session {cfg.session!r} (waited {cfg.wait_s:g} s for it to start)"
                    if exc.code == P.CLOSE_NOT_FOUND and cfg.wait_s > 0
                    else f"{exc.code} {exc.reason}"
                )
                raise ClientError(f"{cfg.url}: cannot watch session {cfg.session!r}: {why}") from None
            if time.monotonic() - asked >= RETRY_S:
                continue  # held, then let go early (the server's longest wait; started in another worker)
        except OSError as exc:
            if time.monotonic() >= deadline:
                raise ClientError(f"{cfg.url}: cannot connect: {exc}") from None
        await asyncio.sleep(RETRY_S if waits is None else next(waits))


async def record_stream(cfg: ViewerStreamConfig, *, on_frame=None, check_description=None) -> Recording:
    """Collect the session until it ends (or max_s of frames); ``on_frame(message)`` is called for
    every frame as it arrives (for progress or live display); ``check_description(description)`` right
    after connecting, before any frame: what it raises ends the watch at once (a take that cannot be
    written is refused at its start, not after it)."""
    v = await connect_viewer(cfg)
    if check_description is not None:
        try:
            check_description(v.description)
        except BaseException:
            await v.__aexit__(None, None, None)
            raise
    rec = Recording(description=v.description)
    keep = np.float16 if cfg.kind == "deltas" else np.float32
    try:
        async for m in v:
            if m.kind == P.KIND_AUDIO:
                rec.audio.append((m.media_time, m.values))
                continue
            rec.index.append(m.index)
            rec.media_time.append(m.media_time)
            rec.values.append(m.values.astype(keep))
            if on_frame is not None:
                on_frame(m)
            if cfg.max_s is not None and m.media_time - rec.media_time[0] >= cfg.max_s:
                rec.stopped = True
                break
    finally:
        await v.__aexit__(None, None, None)
    rec.close_code, rec.close_reason = v.close_code, v.close_reason
    return rec


async def live_sessions(url: str, token: str | None = None) -> list[str]:
    """Names of the server's live sessions (``/sessions``: cluster-wide behind Redis; the token when
    the server has one)."""
    path = "/sessions" + (f"?token={quote(token)}" if token else "")
    try:
        status, body = await http_get(url, path)
    except OSError as exc:
        raise ClientError(f"{url}: cannot connect: {exc}") from None
    if status != 200:
        hint = " (wrong or missing token)" if status == 401 else ""
        raise ClientError(f"{url}: /sessions answered {status}{hint}")
    return [s["name"] for s in json.loads(body).get("sessions", [])]


async def pick_session(url: str, wanted: str | None, wait_s: float, token: str | None = None) -> str:
    """``wanted`` if given, else the first live session, waiting up to wait_s for one to start."""
    if wanted is not None:
        return wanted
    deadline = time.monotonic() + wait_s
    while True:
        names = await live_sessions(url, token)
        if names:
            return names[0]
        if time.monotonic() >= deadline:
            raise ClientError(f"{url}: no live session (waited {wait_s:g} s); start one or pass --session")
        await asyncio.sleep(RETRY_S)
