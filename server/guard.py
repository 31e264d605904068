"""Guards against hostile or careless clients, without I/O: ingest pacing, Origin and Host checks,
per-client connection counts, and a log that reports repeated client errors once with a count.

Each piece takes the facts (header values, times, counts) as arguments and returns a decision, so
its tests are tables; the asyncio shell (:mod:`server.app`) reads the headers and the clock.
"""

from __future__ import annotations

import ipaddress
import logging
import traceback
import urllib.parse
from collections import Counter
from dataclasses import dataclass, field

LOOPBACK_NAMES = frozenset({"localhost", "127.0.0.1", "::1"})


# -- ingest rate -----------------------------------------------------------------------------------------


@dataclass
class IngestPacer:
    """Real-time pacing of one ingest: audio may run ahead of the wall clock by ``burst_s`` seconds.

    ``delay(audio_s, now)`` is called before ``audio_s`` seconds more of audio are processed, at
    monotonic time ``now`` (s); it returns how long to wait first (0 when within the burst). The
    clock starts at the first call."""

    burst_s: float
    t0: float | None = None
    audio_s: float = 0.0

    def delay(self, audio_s: float, now: float) -> float:
        wait = self.would_wait(audio_s, now)
        if self.t0 is None:
            self.t0 = now
        self.audio_s += audio_s
        return wait

    def would_wait(self, audio_s: float, now: float) -> float:
        """What :meth:`delay` would return, without counting the audio."""
        ahead = self.audio_s + audio_s - (now - (now if self.t0 is None else self.t0))
        return max(0.0, ahead - self.burst_s)


# -- Origin and Host --------------------------------------------------------------------------------------


def host_name(host_header: str) -> str:
    """``Host`` header value -> lower-case host name without port (IPv6 brackets removed)."""
    h = host_header.strip().lower()
    if h.startswith("["):
        return h[1 : h.find("]")] if "]" in h else h
    return h.rsplit(":", 1)[0] if h.count(":") == 1 else h


def _is_loopback(host: str) -> bool:
    if host in LOOPBACK_NAMES or host.endswith(".localhost"):
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def host_allowed(host_header: str | None, *, bound_host: str, allowed: tuple[str, ...] | None) -> bool:
    """Is this ``Host`` header acceptable? Against DNS rebinding: a server bound to loopback answers
    only loopback names unless ``allowed`` lists others; ``allowed`` (names, ``*`` = any) wins."""
    if host_header is None:
        return False  # HTTP/1.1 requires Host; websockets' clients and browsers always send it
    name = host_name(host_header)
    if allowed is not None:
        return "*" in allowed or name in allowed
    if _is_loopback(host_name(bound_host)):
        return _is_loopback(name)
    return True


WILDCARD_HOSTS = {"0.0.0.0": "127.0.0.1", "": "127.0.0.1", "::": "::1"}
"""A server bound to every interface is reached from its own machine at the loopback address."""


def http_url(host: str, port: int) -> str:
    """``http://host:port``, an IPv6 address in brackets (``http://::1:8765`` is no URL)."""
    return f"http://[{host}]:{port}" if ":" in host else f"http://{host}:{port}"


def client_url(bound_host: str, port: int, allowed: tuple[str, ...] | None) -> str | None:
    """A URL of a server bound to ``bound_host``:``port`` whose Host the Host check (:func:`host_allowed`)
    accepts: the bound address (loopback for every interface), else a loopback name ``allowed`` lists for a server
    on loopback; None when ``allowed`` admits none of them (clients must come by a name it lists: a proxy, DNS).
    ``facecast serve`` printed the bound address whatever ``allowed_hosts`` said: every request to it was 403."""
    host = WILDCARD_HOSTS.get(bound_host, bound_host)
    candidates = [host]
    if _is_loopback(host):
        candidates += sorted(LOOPBACK_NAMES - {host})
    for name in candidates:
        url = http_url(name, port)
        if host_allowed(urllib.parse.urlsplit(url).netloc, bound_host=bound_host, allowed=allowed):
            return url
    return None


def origin_allowed(origin: str | None, host_header: str | None, allowed: tuple[str, ...]) -> bool:
    """Is a WebSocket upgrade with this ``Origin`` acceptable? No Origin (not a browser): yes;
    ``null`` (sandboxed frames, file: pages): no; same origin as ``Host``, or listed: yes."""
    if origin is None:
        return True
    o = origin.strip().lower()
    if o == "null" or not o:
        return False
    if "*" in allowed or o in allowed:
        return True
    netloc = urllib.parse.urlsplit(o).netloc
    return host_header is not None and netloc == host_header.strip().lower()


# -- connections per client -------------------------------------------------------------------------------


@dataclass
class ConnectionCounter:
    """Open WebSocket connections per remote address, against ``limit`` (0 = no limit)."""

    limit: int
    open: Counter = field(default_factory=Counter)

    def full(self, address: str) -> bool:
        return self.limit > 0 and self.open[address] >= self.limit

    def add(self, address: str) -> None:
        self.open[address] += 1

    def remove(self, address: str) -> None:
        self.open[address] -= 1
        if self.open[address] <= 0:
            del self.open[address]


@dataclass
class ConnectionRate:
    """New WebSocket connections per remote address: a token bucket of ``burst`` connections refilled
    at ``per_s`` a second (per_s 0 = no limit). Bounds what a client reconnecting in a tight loop
    can make the server do: beyond the bucket it gets a cheap 429 before any handshake."""

    per_s: float
    burst: int
    _buckets: dict = field(default_factory=dict)

    def allow(self, address: str, now: float) -> bool:
        if self.per_s <= 0:
            return True
        tokens, last = self._buckets.get(address, (float(self.burst), now))
        tokens = min(float(self.burst), tokens + (now - last) * self.per_s)
        if tokens < 1.0:
            self._buckets[address] = (tokens, now)
            return False
        self._buckets[address] = (tokens - 1.0, now)
        if len(self._buckets) > 10000:  # forget full buckets (idle clients) so the table stays small
            self._buckets = {a: (t, n) for a, (t, n) in self._buckets.items() if t < self.burst}
        return True


# -- logging repeated errors once --------------------------------------------------------------------------


class IncidentLog:
    """Logs the first occurrence of each kind of incident, counts the repeats, and reports the count
    at most once per ``every_s`` seconds: a client sending 10,000 bad messages costs a few lines, not
    10,000 (and never a traceback per message)."""

    def __init__(self, logger: logging.Logger, *, every_s: float = 60.0, max_kinds: int = 1000) -> None:
        self.log = logger
        self.every_s = every_s
        self.max_kinds = max_kinds
        self.counts: Counter[str] = Counter()
        self._reported: dict[str, tuple[float, int]] = {}

    def client_error(self, code: int, reason: str, now: float) -> None:
        """A connection was closed for a protocol breach (INFO, once per code and reason text)."""
        self._note(f"{code} {reason[:60]}", now, logging.INFO, f"closed a client connection: {code} {reason}")

    def internal_error(self, where: str, exc: BaseException, now: float) -> None:
        """A bug surfaced in one connection's handler (ERROR with the traceback, once per place)."""
        tb = traceback.extract_tb(exc.__traceback__)
        site = f"{tb[-1].filename}:{tb[-1].lineno}" if tb else "?"
        key = f"internal {type(exc).__name__} at {site}"
        if key not in self.counts:
            self.log.error("internal error on %s", where, exc_info=exc)
        self._note(key, now, logging.ERROR, None)

    def _note(self, key: str, now: float, level: int, first: str | None) -> None:
        if key not in self.counts and len(self.counts) >= self.max_kinds:
            key = "other incidents"
        self.counts[key] += 1
        n = self.counts[key]
        if n == 1:
            if first is not None:
                self.log.log(level, "%s", first)
            self._reported[key] = (now, 1)
            return
        last_t, last_n = self._reported[key]
        if now - last_t >= self.every_s:
            self.log.log(level, "%d more: %s (%d in all)", n - last_n, key, n)
            self._reported[key] = (now, n)
