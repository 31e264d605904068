"""The guards as tables: Origin, Host, pacing, connection counts, logging repeated errors once."""

from __future__ import annotations

import logging

import pytest

from server.guard import (
    ConnectionCounter,
    ConnectionRate,
    IncidentLog,
    IngestPacer,
    client_url,
    host_allowed,
    host_name,
    origin_allowed,
)

# (Origin header, Host header, allow-list, accepted?)
ORIGINS = [
    (None, "127.0.0.1:8765", (), True),  # not a browser
    ("http://127.0.0.1:8765", "127.0.0.1:8765", (), True),  # same origin
    ("HTTP://127.0.0.1:8765", "127.0.0.1:8765", (), True),
    ("http://localhost:8765", "127.0.0.1:8765", (), False),  # another origin, not listed
    ("http://evil.example", "127.0.0.1:8765", (), False),
    ("null", "127.0.0.1:8765", (), False),  # sandboxed frame / file: page
    ("null", "127.0.0.1:8765", ("*",), False),  # never, even with a wildcard
    ("", "127.0.0.1:8765", (), False),
    ("http://app.example", "127.0.0.1:8765", ("http://app.example",), True),
    ("http://other.example", "127.0.0.1:8765", ("*",), True),
    ("http://127.0.0.1:9999", "127.0.0.1:8765", (), False),  # another port is another origin
]


@pytest.mark.parametrize("origin, host, allowed, ok", ORIGINS)
def test_origin(origin, host, allowed, ok):
    assert origin_allowed(origin, host, allowed) is ok


# (Host header, bound host, allowed_hosts, accepted?)
HOSTS = [
    ("127.0.0.1:8765", "127.0.0.1", None, True),
    ("localhost:8765", "127.0.0.1", None, True),
    ("[::1]:8765", "127.0.0.1", None, True),
    ("app.localhost", "127.0.0.1", None, True),
    ("evil.example:8765", "127.0.0.1", None, False),  # DNS rebinding: a public name pointing at loopback
    ("127.0.0.1.evil.example", "127.0.0.1", None, False),
    (None, "127.0.0.1", None, False),
    ("anything.example", "0.0.0.0", None, True),  # bound to every interface: the operator decides
    ("anything.example", "0.0.0.0", ("face.example",), False),
    ("FACE.example:443", "0.0.0.0", ("face.example",), True),
    ("evil.example", "127.0.0.1", ("*",), True),
]


@pytest.mark.parametrize("host, bound, allowed, ok", HOSTS)
def test_host(host, bound, allowed, ok):
    assert host_allowed(host, bound_host=bound, allowed=allowed) is ok


# (bound host, allowed_hosts, the URL `facecast serve` prints, None: none the Host check accepts)
CLIENT_URLS = [
    ("127.0.0.1", None, "http://127.0.0.1:8765"),
    ("127.0.0.1", ("localhost",), "http://localhost:8765"),  # was http://127.0.0.1:8765: 403
    ("127.0.0.1", ("face.example.org", "10.0.0.11"), None),  # docs/deploy.md's node config as printed
    ("0.0.0.0", None, "http://127.0.0.1:8765"),
    ("0.0.0.0", ("face.example.org",), None),
    ("::", None, "http://[::1]:8765"),
    ("::1", None, "http://[::1]:8765"),  # was http://::1:8765
    ("10.0.0.11", ("face.example.org", "10.0.0.11"), "http://10.0.0.11:8765"),
    ("127.0.0.1", ("*",), "http://127.0.0.1:8765"),
]


@pytest.mark.parametrize("bound, allowed, url", CLIENT_URLS)
def test_the_printed_url_is_one_the_host_check_accepts(bound, allowed, url):
    got = client_url(bound, 8765, allowed)
    assert got == url
    if got is not None:  # independently: the Host a client sends for it passes
        assert host_allowed(got.removeprefix("http://"), bound_host=bound, allowed=allowed)


def test_host_name():
    assert [host_name(h) for h in ("a:1", "[::1]:80", "::1", "A.B")] == ["a", "::1", "::1", "a.b"]


def test_pacer_allows_the_burst_then_holds_to_real_time():
    p = IngestPacer(burst_s=2.0)
    assert p.delay(2.0, now=100.0) == 0.0  # 2 s at once: within the burst
    assert p.delay(1.0, now=100.0) == pytest.approx(1.0)  # 3 s ahead: wait 1 s
    assert p.delay(0.5, now=101.5) == pytest.approx(0.0)  # 3.5 s of audio at 1.5 s: 2 s ahead
    assert p.delay(10.0, now=101.5) == pytest.approx(10.0)  # a 100x burst waits for real time


def test_connection_counter():
    c = ConnectionCounter(limit=2)
    c.add("a")
    assert not c.full("a")
    c.add("a")
    assert c.full("a") and not c.full("b")
    c.remove("a")
    assert not c.full("a")
    assert not ConnectionCounter(limit=0).full("a")


def test_incidents_are_logged_once_with_a_count(caplog):
    log = logging.getLogger("test.incidents")
    inc = IncidentLog(log, every_s=60)
    with caplog.at_level(logging.INFO, logger="test.incidents"):
        for i in range(10000):
            inc.client_error(1007, "start message is not valid JSON", now=i * 0.001)
        inc.client_error(1007, "start message is not valid JSON", now=100.0)
        try:
            raise RecursionError("deep")
        except RecursionError as exc:
            for _ in range(500):
                inc.internal_error("/ingest", exc, now=1.0)
    lines = [r.getMessage() for r in caplog.records]
    assert len(lines) == 3, lines
    assert "1007 start message is not valid JSON" in lines[0]
    assert lines[1].startswith("10000 more") and "(10001 in all)" in lines[1]
    assert sum(r.exc_info is not None for r in caplog.records) == 1  # one traceback for 500 errors


def test_connection_rate_bucket():
    r = ConnectionRate(per_s=10, burst=3)
    assert [r.allow("a", 0.0) for _ in range(4)] == [True, True, True, False]
    assert r.allow("b", 0.0)  # per address
    assert not r.allow("a", 0.05) and r.allow("a", 0.2)  # refilled at 10/s
    assert all(ConnectionRate(per_s=0, burst=0).allow("a", 0.0) for _ in range(100))
