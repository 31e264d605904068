"""Plain HTTP on the service's port: a small router answering GET requests before any WebSocket handshake.

Routes: ``/health``, ``/metrics``, ``/sessions``, ``/head/mesh`` (binary glTF), ``/head/mesh.json``,
``/head/description.json`` (the head and its rest, for a page waiting for a session), ``/head/texture``, ``/``
(the web root's ``index.html``, else a generated session list), then static files under the web root,
``/js/protocol.js`` (the wire format's JS twin) and ``/vendor/three/...`` (three.js from ``node_modules``).
One MIME table: the standard library's :mod:`mimetypes`, with the few types it lacks added to a private
instance (no change to global state).

The router returns an :class:`HttpReply` (status, body, content type); the asyncio shell turns it into
a websockets ``Response``. Exact routes are a dict (:meth:`HttpRouter.route` adds one), so other parts
of the server add endpoints without touching this file's dispatch.
"""

from __future__ import annotations

import errno
import html
import mimetypes
from collections.abc import Callable
from dataclasses import dataclass
from http import HTTPStatus
from pathlib import Path
from typing import TYPE_CHECKING

from assets.heads.glb import mesh_glb, mesh_json, texture_mime
from server.describe import head_at_rest
from wire import JS_PROTOCOL
from wire import protocol as P

if TYPE_CHECKING:
    from assets.heads.head import Head

MAX_PATH_CHARS = 1024  # longer request paths are refused with 414 before touching the file system

# Files of npm packages the browser viewer imports (its import map points at /vendor/three/).
VENDOR_DIRS = {"three": ("build/", "examples/jsm/")}


def _mime_table() -> mimetypes.MimeTypes:
    table = mimetypes.MimeTypes()
    # Types some platforms' tables lack or spell the old way; browsers need these exact ones.
    for ext, ctype in (
        (".js", "text/javascript"),
        (".mjs", "text/javascript"),
        (".glb", "model/gltf-binary"),
        (".gltf", "model/gltf+json"),
        (".wasm", "application/wasm"),
        (".json", "application/json"),
    ):
        table.add_type(ctype, ext)
    return table


@dataclass(frozen=True)
class HttpReply:
    status: HTTPStatus
    body: bytes
    content_type: str

    @classmethod
    def text(cls, status: HTTPStatus, text: str) -> HttpReply:
        return cls(status, text.encode(), "text/plain; charset=utf-8")

    @classmethod
    def json(cls, obj: dict, status: HTTPStatus = HTTPStatus.OK) -> HttpReply:
        return cls(status, P.dumps(obj).encode(), "application/json")


NOT_FOUND = HttpReply.text(HTTPStatus.NOT_FOUND, "not found\n")
UNAUTHORIZED = HttpReply.text(
    HTTPStatus.UNAUTHORIZED, "missing or wrong token (?token=... or Authorization: Bearer ...)\n"
)

Handler = Callable[[], HttpReply]


class HttpRouter:
    """GET path -> HttpReply.

    web_root: directory served at ``/`` (None: a generated index); node_modules: npm packages for
    ``/vendor/`` (None: not served); head: the served head (None: ``/head/*`` answer 404);
    sessions: () -> rows for the generated index page (name, source, frames, viewers)."""

    def __init__(
        self,
        *,
        web_root: Path | None,
        node_modules: Path | None,
        head: Head | None,
        sessions: Callable[[], list[dict]],
    ) -> None:
        self.web_root = web_root.resolve() if web_root is not None else None
        self.node_modules = node_modules.resolve() if node_modules is not None else None
        self.head = head
        self.sessions = sessions
        self.routes: dict[str, tuple[Handler, bool]] = {"/": (self._index, False), "/index.html": (self._index, False)}
        self._authorized = True
        self._mime = _mime_table()
        self._cache: dict[str, HttpReply] = {}

    def route(self, path: str, handler: Handler, *, private: bool = True) -> None:
        """Answer GET ``path`` with ``handler()``; a private route needs the token (else 401)."""
        self.routes[path] = (handler, private)

    def handle(self, path: str, *, authorized: bool = True) -> HttpReply:
        """authorized: the request showed the server's token (or the server has none). Private routes
        and the head downloads need it; static files do not; the generated index lists sessions only
        with it."""
        if len(path) > MAX_PATH_CHARS:
            return HttpReply.text(HTTPStatus.REQUEST_URI_TOO_LONG, "request path too long\n")
        hit = self.routes.get(path)
        private = hit[1] if hit is not None else path.startswith("/head/")
        if private and not authorized:
            return UNAUTHORIZED
        self._authorized = authorized
        if hit is not None:
            return hit[0]()
        if path.startswith("/head/"):
            return self._head(path)
        return self._static(path)

    # -- head downloads -----------------------------------------------------------------------------

    def _head(self, path: str) -> HttpReply:
        if self.head is None:
            return HttpReply.text(HTTPStatus.NOT_FOUND, "this server has no head\n")
        hit = self._cache.get(path)
        if hit is None:
            mesh = self.head.mesh
            if path == "/head/mesh":
                hit = HttpReply(HTTPStatus.OK, mesh_glb(mesh), "model/gltf-binary")
            elif path == "/head/mesh.json":
                # The targets the head drives, in the order of the morph kind's weights (none for a retarget).
                names = tuple(getattr(self.head.rig, "names", ())) if self.head.kind == "morph" else ()
                hit = HttpReply(HTTPStatus.OK, mesh_json(mesh, names), "application/json")
            elif path == "/head/description.json":
                hit = HttpReply.json(head_at_rest(self.head))
            elif path == "/head/texture" and mesh.texture is not None:
                hit = HttpReply(HTTPStatus.OK, mesh.texture, texture_mime(mesh) or "application/octet-stream")
            else:
                return NOT_FOUND
            self._cache[path] = hit
        return hit

    # -- index and static files ---------------------------------------------------------------------

    def _index(self) -> HttpReply:
        if self.web_root is not None and (self.web_root / "index.html").is_file():
            return self._file(self.web_root / "index.html")
        if not self._authorized:
            return HttpReply(
                HTTPStatus.OK,
                b"<!doctype html><meta charset=utf-8><title>facecast</title><h1>facecast</h1>"
                b"<p>This server needs a token: add ?token=... to the address.</p>",
                "text/html; charset=utf-8",
            )
        rows = (
            "".join(
                f"<li><code>{html.escape(s['name'])}</code> ({s['frames']} frames, {s['viewers']} viewers): "
                f"<code>ws://HOST/view?session={html.escape(s['name'])}&amp;kind=params</code></li>"
                for s in sorted(self.sessions(), key=lambda s: s["name"])
            )
            or "<li>none</li>"
        )
        page = (
            "<!doctype html><meta charset=utf-8><title>facecast</title>"
            "<h1>facecast</h1><p>No browser viewer directory is configured (web_root). Live sessions:</p>"
            f"<ul>{rows}</ul><p>See <a href=/health>/health</a>, <a href=/metrics>/metrics</a>, "
            "<a href=/head/mesh>/head/mesh</a> (glTF) and docs/protocol.md.</p>"
        )
        return HttpReply(HTTPStatus.OK, page.encode(), "text/html; charset=utf-8")

    def _static(self, path: str) -> HttpReply:
        root, rel = self.web_root, path.lstrip("/")
        if path == "/js/protocol.js":  # the wire format's JS twin lives with the Python one
            root, rel = JS_PROTOCOL.parent, JS_PROTOCOL.name
        elif path.startswith("/vendor/") and self.node_modules is not None:
            package, _, sub = path[len("/vendor/") :].partition("/")
            prefix = next((d for d in VENDOR_DIRS.get(package, ()) if sub.startswith(d)), None)
            if prefix is not None:  # root = the allowed folder itself, so ../ cannot leave it
                root, rel = self.node_modules / package / prefix, sub[len(prefix) :]
        if root is None or not rel or "\x00" in rel:
            return NOT_FOUND
        try:
            target = (root / rel).resolve()
            if root.resolve() not in target.parents or not target.is_file():
                return NOT_FOUND
            return self._file(target)
        except OSError as exc:  # a name too long for the file system, a loop of links: not found, not a 500
            if exc.errno == errno.ENAMETOOLONG:
                return HttpReply.text(HTTPStatus.REQUEST_URI_TOO_LONG, "request path too long\n")
            return NOT_FOUND

    def _file(self, target: Path) -> HttpReply:
        ctype, _ = self._mime.guess_type(target.name)
        if ctype is None:
            ctype = "application/octet-stream"
        elif ctype == "text/html":
            ctype = "text/html; charset=utf-8"
        return HttpReply(HTTPStatus.OK, target.read_bytes(), ctype)
