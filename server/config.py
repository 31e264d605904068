"""Server configuration: one frozen dataclass, validated once; optionally read from a TOML file."""

from __future__ import annotations

import ipaddress
import re
import tomllib
from dataclasses import dataclass, fields, replace
from pathlib import Path
from typing import Any

from server.errors import ServerConfigError
from server.eventloop import DEFAULT_EVENT_LOOP, EVENT_LOOPS, loop_available

P_NODE = re.compile(r"^[A-Za-z0-9_.-]{1,64}$")


@dataclass(frozen=True, kw_only=True)
class ServerConfig:
    """host: interface to bind (127.0.0.1 = this machine only); port: TCP port (0 = any free port);
    token: shared secret required from ingest and viewers (None = open); max_message_bytes: largest
    WebSocket message accepted (larger ones close that connection with 1009; 4 MiB by default so that a start
    carrying 60 s of enrolment fits: 60 s of 16 kHz s16 mono is 2.6 MB in base64, of 24 kHz 3.8 MB. Other text
    messages stay under protocol.MAX_TEXT_BYTES. A maximal start costs the server ~40 MiB while it is parsed and checked
    (tracemalloc: 35 MiB beyond the 4 MiB frame: its text, the JSON string, the decoded bytes, float copies of the
    samples), before the adaptation's own work; a binary audio message of 4 MiB costs about its size); max_sessions /
    max_viewers: server-wide limits (over them a connection is closed with 1013); viewer_queue:
    messages buffered per viewer before the oldest is dropped; viewer_max_behind_s: a viewer that
    keeps dropping for this long is closed (4000); start_timeout_s: time an ingest connection has to
    send its start message; close_timeout_s: wait for a peer's close handshake before dropping TCP;
    lag: extra fixed-lag smoothing frames of every session; auto_gain: every audio session whose start does not say
    otherwise brings its input to the model's training speech level first (a quiet microphone opened the mouth about
    half as far at 20 dB under; realtime_core.features.gain.InputGainConfig, docs/protocol.md); workers: compute
    processes for the sessions' per-frame work (0: on the event loop); worker_mode: what a worker process takes,
    "compute" (a session's per-frame work, its sockets stay on the front's loop; server.workers) or "connections"
    (whole sessions with their ingest and viewer sockets; server.shards); viewer_socket_buffer_bytes: kernel send
    buffer of viewer sockets (None = the OS's autotuned default, up to megabytes: a small one makes a stalled viewer
    show up as behind within a few frames instead of seconds); web_root: directory served at ``/`` (None: a
    generated index page listing the sessions); node_modules: npm packages directory from which ``/vendor/three/``
    serves three.js's ``build/`` and ``examples/jsm/`` to the browser viewer (None: not served); event_loop: the
    loop ``facecast serve`` and its connection workers run on, "uvloop" (the default on Linux: less CPU per received
    block, docs/service.md "uvloop") or "asyncio" (the standard loop; the default elsewhere); the front of
    connection workers always runs on asyncio's (server.eventloop.process_loop), and a server run inside a caller's
    loop (``run_server``) uses that loop.

    Hardening (docs/protocol.md section 7): ingest_burst_s: seconds of audio an ingest may run ahead
    of real time before it is paced (or closed with 4029 when ingest_overrun is "close"); batch
    sessions (start message ``"batch": true``) are exempt, at most max_batch_sessions at a time;
    allowed_origins: extra Origin values accepted on WebSocket upgrades besides same-origin
    (``"*"`` accepts any; a ``null`` Origin is always refused; clients that send no Origin, i.e.
    not browsers, are accepted); allowed_hosts: Host header names accepted (None: loopback names
    when bound to loopback, else any); max_connections_per_client: open WebSocket connections per
    remote address; connect_rate_per_s / connect_burst: new WebSocket connections per remote address
    (a token bucket; beyond it 429; rate 0 = no limit); handshake_timeout_s: time to complete the
    opening handshake; idle_timeout_s: an ingest that sends nothing for this long is closed (1008);
    max_view_wait_s: the longest a viewer may ask (query ``wait``) to be held for a session not yet started.

    Cluster (docs/deploy.md): redis_url: the Redis every node of a cluster shares (None: one
    process, no Redis); node_id: this node's name in the registry (None: host-pid-port);
    advertise_url: the http:// URL clients reach this node at (None: the bound address);
    heartbeat_s: registry refresh period (rows expire after 3 heartbeats); role: "both" (compute
    sessions and serve viewers), "compute", or "edge" (serve viewers; forward ingests to a computing
    node)."""

    host: str = "127.0.0.1"
    port: int = 8765
    token: str | None = None
    max_message_bytes: int = 4 << 20
    max_sessions: int = 200
    max_viewers: int = 2000
    viewer_queue: int = 16
    viewer_max_behind_s: float = 3.0
    start_timeout_s: float = 10.0
    close_timeout_s: float = 2.0
    lag: int = 0
    auto_gain: bool = False
    workers: int = 0
    worker_mode: str = "compute"
    viewer_socket_buffer_bytes: int | None = None
    web_root: Path | None = None
    node_modules: Path | None = None
    ingest_burst_s: float = 2.0
    ingest_overrun: str = "pace"
    max_batch_sessions: int = 2
    allowed_origins: tuple[str, ...] = ()
    allowed_hosts: tuple[str, ...] | None = None
    max_connections_per_client: int = 1024
    connect_rate_per_s: float = 50.0
    connect_burst: int = 1000
    handshake_timeout_s: float = 10.0
    idle_timeout_s: float = 60.0
    max_view_wait_s: float = 60.0
    redis_url: str | None = None
    node_id: str | None = None
    advertise_url: str | None = None
    heartbeat_s: float = 1.0
    role: str = "both"
    event_loop: str = DEFAULT_EVENT_LOOP

    def __post_init__(self) -> None:
        if not isinstance(self.host, str) or not self.host:
            raise ServerConfigError(f"host must be a non-empty string, got {self.host!r}")
        if self.host not in ("localhost",):
            try:
                ipaddress.ip_address(self.host)
            except ValueError:
                raise ServerConfigError(f"host must be an IP address or 'localhost', got {self.host!r}") from None
        if not isinstance(self.port, int) or not 0 <= self.port <= 65535:
            raise ServerConfigError(f"port must be an integer in 0..65535, got {self.port!r}")
        if self.token is not None and (not isinstance(self.token, str) or not self.token):
            raise ServerConfigError("token must be a non-empty string or absent")
        if not isinstance(self.max_message_bytes, int) or not 1024 <= self.max_message_bytes <= 64 << 20:
            raise ServerConfigError(f"max_message_bytes must be in 1024..{64 << 20}, got {self.max_message_bytes!r}")
        for name in ("max_sessions", "max_viewers", "viewer_queue"):
            v = getattr(self, name)
            if not isinstance(v, int) or not 1 <= v <= 100000:
                raise ServerConfigError(f"{name} must be an integer in 1..100000, got {v!r}")
        for name in (
            "viewer_max_behind_s",
            "start_timeout_s",
            "close_timeout_s",
            "handshake_timeout_s",
            "idle_timeout_s",
            "ingest_burst_s",
            "max_view_wait_s",
        ):
            v = getattr(self, name)
            if not isinstance(v, (int, float)) or not 0 < v <= 3600:
                raise ServerConfigError(f"{name} must be a number of seconds in (0, 3600], got {v!r}")
        if not isinstance(self.workers, int) or not 0 <= self.workers <= 64:
            raise ServerConfigError(f"workers must be an integer in 0..64, got {self.workers!r}")
        if self.worker_mode not in ("compute", "connections"):
            raise ServerConfigError(f"worker_mode must be 'compute' or 'connections', got {self.worker_mode!r}")
        if self.worker_mode == "connections" and self.workers and self.redis_url is not None:
            raise ServerConfigError(
                "worker_mode 'connections' cannot be combined with redis_url yet (use 'compute' workers in a cluster)"
            )
        if not isinstance(self.lag, int) or not 0 <= self.lag <= 30:
            raise ServerConfigError(f"lag must be an integer in 0..30, got {self.lag!r}")
        if not isinstance(self.auto_gain, bool):
            raise ServerConfigError(f"auto_gain must be true or false, got {self.auto_gain!r}")
        b = self.viewer_socket_buffer_bytes
        if b is not None and (not isinstance(b, int) or not 1024 <= b <= 64 << 20):
            raise ServerConfigError(f"viewer_socket_buffer_bytes must be in 1024..{64 << 20} or absent, got {b!r}")
        if self.redis_url is not None and (
            not isinstance(self.redis_url, str) or not self.redis_url.startswith(("redis://", "rediss://", "unix://"))
        ):
            raise ServerConfigError(f"redis_url must be a redis://, rediss:// or unix:// URL, got {self.redis_url!r}")
        if self.node_id is not None and (not isinstance(self.node_id, str) or not P_NODE.match(self.node_id)):
            raise ServerConfigError(f"node_id must be 1-64 characters of A-Z a-z 0-9 _ . -, got {self.node_id!r}")
        if self.advertise_url is not None and (
            not isinstance(self.advertise_url, str) or not self.advertise_url.startswith(("http://", "https://"))
        ):
            raise ServerConfigError(f"advertise_url must be an http:// or https:// URL, got {self.advertise_url!r}")
        if not isinstance(self.heartbeat_s, (int, float)) or not 0.05 <= self.heartbeat_s <= 60:
            raise ServerConfigError(f"heartbeat_s must be in 0.05..60 s, got {self.heartbeat_s!r}")
        if self.role not in ("both", "compute", "edge"):
            raise ServerConfigError(f"role must be 'both', 'compute' or 'edge', got {self.role!r}")
        if self.role == "edge" and self.redis_url is None:
            raise ServerConfigError("role 'edge' needs redis_url (an edge forwards ingests to the cluster's nodes)")
        if self.event_loop not in EVENT_LOOPS:
            raise ServerConfigError(f"event_loop must be one of {EVENT_LOOPS}, got {self.event_loop!r}")
        if not loop_available(self.event_loop):
            raise ServerConfigError(
                f"event_loop {self.event_loop!r}: the package is not installed (pip install uvloop), "
                "or set event_loop = 'asyncio'"
            )
        if self.ingest_overrun not in ("pace", "close"):
            raise ServerConfigError(f"ingest_overrun must be 'pace' or 'close', got {self.ingest_overrun!r}")
        if (
            isinstance(self.connect_rate_per_s, bool)
            or not isinstance(self.connect_rate_per_s, (int, float))
            or not (0 <= self.connect_rate_per_s <= 1e6)
        ):
            raise ServerConfigError(f"connect_rate_per_s must be a number in 0..1e6, got {self.connect_rate_per_s!r}")
        for name in ("max_batch_sessions", "max_connections_per_client", "connect_burst"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or not 0 <= v <= 100000:
                raise ServerConfigError(f"{name} must be an integer in 0..100000, got {v!r}")
        for name in ("allowed_origins", "allowed_hosts"):
            v = getattr(self, name)
            if v is None and name == "allowed_hosts":
                continue
            if isinstance(v, str) or not all(isinstance(x, str) and x for x in v):
                raise ServerConfigError(f"{name} must be a list of non-empty strings, got {v!r}")
            object.__setattr__(self, name, tuple(x.lower() for x in v))
        if "null" in self.allowed_origins:
            raise ServerConfigError("allowed_origins cannot hold 'null': a null Origin is always refused")
        for name in ("web_root", "node_modules"):
            if getattr(self, name) is not None:
                object.__setattr__(self, name, Path(getattr(self, name)))

    @classmethod
    def from_toml(cls, path: str | Path, **overrides: Any) -> ServerConfig:
        """Read the ``[server]`` table of a TOML file (keys = field names; nothing else may be in the file);
        ``overrides`` (non-None) win."""
        p = Path(path)
        try:
            doc = tomllib.loads(p.read_text())
        except FileNotFoundError:
            raise ServerConfigError(f"{p}: config file not found") from None
        except (OSError, tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
            raise ServerConfigError(f"{p}: cannot read config: {exc}") from None
        # Anything outside [server] would be dropped without a word: a misspelled table or a bare
        # `port = ...` above it would start on the defaults (and with no token), so refuse it.
        stray = sorted(set(doc) - {"server"})
        if stray:
            raise ServerConfigError(
                f"{p}: unknown top-level key or table {stray[0]!r} (settings go in the [server] table)"
            )
        table = doc.get("server", {})
        if not isinstance(table, dict):
            raise ServerConfigError(f"{p}: [server] must be a table")
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(table) - known)
        if unknown:
            raise ServerConfigError(f"{p}: unknown [server] keys {unknown} (known: {sorted(known)})")
        try:
            base = cls(**table)
        except (TypeError, ServerConfigError) as exc:  # a bad value names the file it is in
            raise ServerConfigError(f"{p}: {exc}") from None
        return replace(base, **{k: v for k, v in overrides.items() if v is not None})
