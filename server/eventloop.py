"""The event loop the server runs on: uvloop (libuv's loop for asyncio) by default on Linux, or asyncio's own.

Most of a live session's CPU is per-message loop and socket overhead (20 ms ingest blocks, one frame
written to each viewer 30 times a second; docs/service.md, "uvloop"), which libuv's loop does in C:
measured there against asyncio's selector loop, 9-14% less CPU per received block, the same per viewer
write (a system call either way). The
choice is ``ServerConfig.event_loop``; ``"asyncio"`` stays as the fallback (a platform without
uvloop, or to rule the loop out when chasing a bug). Both run the same code: websockets and every
handler only use the asyncio loop API.
"""

from __future__ import annotations

import asyncio
import importlib.util
import sys
from collections.abc import Callable, Coroutine
from typing import Any, TypeVar

EVENT_LOOPS = ("uvloop", "asyncio")
# uvloop is a dependency on Linux only (pyproject's marker): elsewhere the standard loop is the default.
DEFAULT_EVENT_LOOP = "uvloop" if sys.platform == "linux" else "asyncio"

T = TypeVar("T")


def loop_available(name: str) -> bool:
    """Whether the loop ``name`` can be made here (uvloop: the package is installed)."""
    return name == "asyncio" or (name == "uvloop" and importlib.util.find_spec("uvloop") is not None)


def loop_factory(name: str) -> Callable[[], asyncio.AbstractEventLoop]:
    """A new-loop factory for ``asyncio.Runner``: ``"uvloop"`` or ``"asyncio"`` (the standard library's
    default loop, whatever event loop policy is installed)."""
    if name == "uvloop":
        import uvloop

        return uvloop.new_event_loop
    if name == "asyncio":
        return asyncio.DefaultEventLoopPolicy().new_event_loop
    raise ValueError(f"event loop must be one of {EVENT_LOOPS}, got {name!r}")


def run(main: Coroutine[Any, Any, T], name: str) -> T:
    """``asyncio.run(main)`` on a new loop of kind ``name``."""
    with asyncio.Runner(loop_factory=loop_factory(name)) as runner:
        return runner.run(main)


def process_loop(event_loop: str, *, connection_front: bool) -> str:
    """The loop a server process makes: ``event_loop``, except for the front of connection workers
    (``worker_mode = "connections"``), which runs on asyncio's loop: it pauses each new connection in
    ``connection_made`` so that the worker it hands the socket to reads the request itself, and uvloop
    starts reading right after ``connection_made`` whatever the protocol asked (the front would read the
    request, and every session would stay on the front). The workers run on ``event_loop``; the front
    itself only routes (its CPU is ~0.0004 cores per session, docs/service.md)."""
    return "asyncio" if connection_front else event_loop


def running_loop_name() -> str:
    """``"uvloop"`` or ``"asyncio"``: the kind of the running loop (what /metrics reports as ``event_loop``)."""
    loop = asyncio.get_running_loop()
    return "uvloop" if type(loop).__module__.split(".")[0] == "uvloop" else "asyncio"
