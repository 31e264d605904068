"""The HTTP router without sockets: static files and their types, traversal, long paths, the index."""

from __future__ import annotations

from http import HTTPStatus

import pytest

from server.http import HttpRouter


@pytest.fixture()
def router(tmp_path):
    root = tmp_path / "web"
    (root / "js").mkdir(parents=True)
    (root / "index.html").write_text("<h1>viewer</h1>")
    (root / "js" / "main.js").write_text("export {}")
    (root / "style.css").write_text("body{}")
    (root / "blob.xyz123").write_bytes(b"\x00")
    (tmp_path / "secret.txt").write_text("no")
    nm = tmp_path / "node_modules" / "three"
    (nm / "build").mkdir(parents=True)
    (nm / "build" / "three.module.js").write_text("three")
    (nm / "package.json").write_text("{}")
    return HttpRouter(
        web_root=root,
        node_modules=tmp_path / "node_modules",
        head=None,
        sessions=lambda: [{"name": "<a>", "frames": 1, "viewers": 0}],
    )


# (path, status, content type prefix or None)
ROUTES = [
    ("/", HTTPStatus.OK, "text/html; charset=utf-8"),
    ("/index.html", HTTPStatus.OK, "text/html"),
    ("/js/main.js", HTTPStatus.OK, "text/javascript"),
    ("/style.css", HTTPStatus.OK, "text/css"),
    ("/blob.xyz123", HTTPStatus.OK, "application/octet-stream"),
    ("/js/protocol.js", HTTPStatus.OK, "text/javascript"),  # the wire format's JS twin
    ("/vendor/three/build/three.module.js", HTTPStatus.OK, "text/javascript"),
    ("/vendor/three/package.json", HTTPStatus.NOT_FOUND, None),  # only build/ and examples/jsm/
    ("/vendor/three/build/../package.json", HTTPStatus.NOT_FOUND, None),
    ("/../secret.txt", HTTPStatus.NOT_FOUND, None),
    ("/js/../../secret.txt", HTTPStatus.NOT_FOUND, None),
    ("/nope", HTTPStatus.NOT_FOUND, None),
    ("/js", HTTPStatus.NOT_FOUND, None),  # a directory
    ("/a\x00b", HTTPStatus.NOT_FOUND, None),
    ("/head/mesh", HTTPStatus.NOT_FOUND, None),  # no head
    ("/head/description.json", HTTPStatus.NOT_FOUND, None),
    ("/" + "a" * 300, HTTPStatus.REQUEST_URI_TOO_LONG, None),  # one name over the file system's limit
    ("/" + "a/" * 600, HTTPStatus.REQUEST_URI_TOO_LONG, None),
]


@pytest.mark.parametrize("path, status, ctype", ROUTES, ids=[r[0][:40] for r in ROUTES])
def test_routes(router, path, status, ctype):
    reply = router.handle(path)
    assert reply.status == status, reply.body[:200]
    if ctype is not None:
        assert reply.content_type.startswith(ctype)


def test_generated_index_escapes_session_names(tmp_path):
    r = HttpRouter(
        web_root=None, node_modules=None, head=None, sessions=lambda: [{"name": "<script>", "frames": 1, "viewers": 0}]
    )
    body = r.handle("/").body.decode()
    assert "&lt;script&gt;" in body and "<script>" not in body


def test_added_routes_win(router):
    from server.http import HttpReply

    router.route("/health", lambda: HttpReply.json({"status": "ok"}))
    assert router.handle("/health").body == b'{"status":"ok"}'


def test_a_morph_heads_mesh_json_carries_the_driven_targets_in_wire_order(builtin_head):
    """/head/mesh.json of a head driven by its own targets lists them in the rig's order (the order of
    the "morph" kind's weights); weights x those targets are exactly the rig's vertex deltas."""
    import json

    import numpy as np

    from assets.heads.head import builtin_morph_head

    head = builtin_morph_head()
    router = HttpRouter(web_root=None, node_modules=None, head=head, sessions=list)
    m = json.loads(router.handle("/head/mesh.json").body)
    rig = head.rig
    assert m["morph"]["names"] == list(rig.names)
    idx = np.array(m["morph"]["vertices"])
    d = np.array(m["morph"]["deltas"]).reshape(len(rig.names), len(idx), 3)
    p = np.array([0.01, 0.04, 0.3, -0.01])
    full = np.zeros((len(m["vertices"]) // 3, 3))
    full[idx] = np.tensordot(rig.weights(p), d, axes=1)
    want = np.zeros_like(full)
    want[rig.moving] = rig.displacements(p)
    np.testing.assert_allclose(full, want, atol=1e-6 * np.abs(want).max())
    # Each target's normal deltas (issue 12) are relative to the rest normals the browser computes (area-weighted,
    # no welding: three.js's computeVertexNormals), computed here: rest + delta is the normal of rest + target.
    v = np.array(m["vertices"]).reshape(-1, 3)
    tris = np.array(m["triangles"]).reshape(-1, 3)

    def normals(x):
        fn = np.cross(x[tris[:, 1]] - x[tris[:, 0]], x[tris[:, 2]] - x[tris[:, 0]])
        n = np.zeros_like(x)
        for c in range(3):
            np.add.at(n, tris[:, c], fn)
        return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-30)

    turned = np.array(m["morph"]["normals"]["vertices"])
    jaw = rig.names.index("jawOpen")
    moved = v.copy()
    moved[idx] += d[jaw]
    lit = normals(v)
    lit[turned] += np.array(m["morph"]["normals"]["deltas"][jaw]).reshape(-1, 3)
    np.testing.assert_allclose(lit, normals(moved), atol=2e-4)  # 4 decimals sent
    assert np.abs(normals(moved) - normals(v)).max() > 0.3  # the jaw does turn the surface


def test_the_head_at_rest_is_served_for_a_page_waiting_for_a_session(head):
    """/head/description.json: what a viewer's description says of the head, and its rest values for each kind the
    head serves, so a page waiting for a session shows the head at rest. The two kinds agree: the rest weights
    times the head's own targets (mesh.json) are the rest deltas; a retargeted head serves deltas only (at rest 0:
    null); the route is private like the other head downloads."""
    import json

    import numpy as np

    from assets.heads.head import builtin_morph_head

    retargeted, head = head, builtin_morph_head()
    router = HttpRouter(web_root=None, node_modules=None, head=head, sessions=list)
    reply = router.handle("/head/description.json")
    assert reply.status == HTTPStatus.OK and reply.content_type == "application/json"
    d = json.loads(reply.body)
    assert d["head"]["morph"]["names"] == list(head.rig.names)
    assert d["head"]["moving_vertices"] == head.rig.moving.tolist()
    assert set(d["rest_values"]) == {"morph", "deltas"}
    m = json.loads(router.handle("/head/mesh.json").body)
    targets = np.array(m["morph"]["deltas"]).reshape(len(head.rig.names), -1, 3)
    weights = (
        np.zeros(len(head.rig.names)) if d["rest_values"]["morph"] is None else np.array(d["rest_values"]["morph"])
    )
    full = np.zeros((len(m["vertices"]) // 3, 3))
    full[np.array(m["morph"]["vertices"])] = np.tensordot(weights, targets, axes=1)
    deltas = d["rest_values"]["deltas"]
    want = np.zeros((len(head.rig.moving), 3)) if deltas is None else np.array(deltas).reshape(-1, 3)
    np.testing.assert_allclose(full[head.rig.moving], want, atol=1e-6)
    assert router.handle("/head/description.json", authorized=False).status == HTTPStatus.UNAUTHORIZED

    retarget = json.loads(
        HttpRouter(web_root=None, node_modules=None, head=retargeted, sessions=list)
        .handle("/head/description.json")
        .body
    )
    assert retarget["head"]["morph"] is None and set(retarget["rest_values"]) == {"deltas"}
