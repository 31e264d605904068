"""Mouth close-ups of test-set (or held-out) heads, per pose, front or three-quarter, optionally with face ids.

    python scripts/mouth_closeups.py --out D --only 3810 --view three_quarter [--ids] [--heldout]

Renders the mouth crop of ``head_testset.mouth_renderer`` (CLOSE_UP_WIDTH IOD wide, 400x300 per pose) at
``head_testset.POSES`` (or at each ``--pose``) for every head whose name contains ``--only``, as one PNG per head
and view (``D/SLUG_VIEW.png``). ``--ids``: also a face-id pass (``D/SLUG_VIEW_ids.npz``: (poses, h, w) int32, -1 =
background), a picture painting every visible triangle in a colour of its id (``D/SLUG_VIEW_ids.png``), and
the close-ups with every visible back face of the head (mouth cavity left out) tinted red
(``D/SLUG_VIEW_backs.png``: what the renderer draws dark; ``realtime_core.face.checks.lip_backs_seen`` measures
it); what a shard is made of is then read off the pixels:
``python -c "import numpy as np; print(np.unique(np.load('D/x_ids.npz')['ids'][1, 120:140, 60:90]))"``.
Heads are made as the test set makes them (``--data``, ``--build``); nothing is checked here.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "scripts"))
from assets.shared import shared_data_root  # noqa: E402 (after the path: a worktree's own package)

_ID_VS = """
#version 330
uniform mat4 mvp;
in vec3 in_pos;
void main() { gl_Position = mvp * vec4(in_pos, 1.0); }
"""
# The triangle's index + 1 in the colour's three bytes (0 = background): exact, no blending (no MSAA).
_ID_FS = """
#version 330
out vec4 f_color;
void main() {
    int k = gl_PrimitiveID + 1;
    f_color = vec4(float(k & 255), float((k >> 8) & 255), float((k >> 16) & 255), 255.0) / 255.0;
}
"""


def face_ids(renderer, vertices: np.ndarray) -> np.ndarray:
    """(h, w) int32: the index of the triangle seen at each pixel of ``renderer``'s view of ``vertices`` (n, 3),
    -1 where nothing is."""
    import moderngl

    ctx = renderer.ctx
    w, h = renderer.config.width, renderer.config.height
    prog = ctx.program(vertex_shader=_ID_VS, fragment_shader=_ID_FS)
    prog["mvp"].write(renderer.mvp.T.astype(np.float32).tobytes())
    buf = ctx.buffer(np.ascontiguousarray(vertices, dtype=np.float32).tobytes())
    vao = ctx.vertex_array(prog, [(buf, "3f", "in_pos")], index_buffer=renderer.ibo)
    fbo = ctx.framebuffer(
        color_attachments=[ctx.renderbuffer((w, h), 4)], depth_attachment=ctx.depth_renderbuffer((w, h))
    )
    fbo.use()
    fbo.clear(0.0, 0.0, 0.0, 1.0, depth=1.0)
    ctx.enable(moderngl.DEPTH_TEST)
    ctx.disable(moderngl.CULL_FACE)
    vao.render(moderngl.TRIANGLES)
    raw = np.frombuffer(fbo.read(components=3, alignment=1), dtype=np.uint8).reshape(h, w, 3)[::-1].astype(np.int32)
    for o in (vao, buf, prog, fbo):
        o.release()
    return raw[..., 0] + (raw[..., 1] << 8) + (raw[..., 2] << 16) - 1


def id_picture(ids: np.ndarray) -> np.ndarray:
    """(h, w, 3) uint8: each triangle id a pseudo-random colour, background black."""
    rng = np.random.default_rng(0)
    lut = rng.integers(40, 256, size=(int(ids.max()) + 2, 3), dtype=np.uint8)
    lut[0] = 0
    return lut[ids + 1]


def back_faces(renderer, rest: np.ndarray, vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """(m,) bool: triangles wound the other way on ``renderer``'s screen than the head's front (the winding most
    triangles seen at ``rest`` have), at ``vertices``: the faces the renderer draws as back faces (dark)."""

    def wound(v: np.ndarray) -> np.ndarray:
        s = renderer.project(v)
        a, b, c = s[triangles[:, 0]], s[triangles[:, 1]], s[triangles[:, 2]]
        return (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])

    seen = np.unique(face_ids(renderer, rest))
    front = np.sign(np.median(wound(rest)[seen[seen >= 0]]))
    return wound(vertices) * front < 0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True, help="directory for the pictures")
    ap.add_argument("--only", required=True, help="the heads whose name contains this text")
    ap.add_argument("--view", choices=("front", "three_quarter"), default="three_quarter")
    ap.add_argument("--scale", type=int, default=1, help="pixels per close-up pixel (same crop, sharper)")
    ap.add_argument("--ids", action="store_true", help="also a face-id pass (npz + picture)")
    ap.add_argument(
        "--pose",
        action="append",
        default=[],
        metavar="LABEL=A,B,C,D",
        help="a pose to render instead of head_testset.POSES (the four parameters, IOD); repeatable",
    )
    ap.add_argument("--heldout", action="store_true", help="the held-out heads (heldout_heads.py), not the test set")
    ap.add_argument("--build", type=Path, default=REPO / "build" / "heads", help="where derived head files go")
    ap.add_argument("--data", type=Path, default=shared_data_root())
    args = ap.parse_args()

    from head_testset import POSES, _resolve, mouth_renderer
    from PIL import Image, ImageDraw

    from clients.render.landmarks import find_landmarks
    from clients.render.renderer import RenderConfig

    if args.heldout:
        import heldout_heads

        heads = heldout_heads.derive(args.build, args.data)
    else:
        import head_testset

        heads = head_testset.derive(args.build, args.data)
    heads = {k: v for k, v in heads.items() if args.only.lower() in k.lower()}
    poses: dict[str, tuple[float, ...]] = dict(POSES)
    if args.pose:
        poses = {}
        for spec in args.pose:
            label, _, values = spec.partition("=")
            poses[label] = tuple(float(x) for x in values.split(","))
            if len(poses[label]) != 4:
                ap.error(f"--pose {spec!r}: four parameters expected")
    if not heads:
        print(f"no head's name contains {args.only!r}", file=sys.stderr)
        return 2
    args.out.mkdir(parents=True, exist_ok=True)
    for name, (spec, opts) in heads.items():
        head = _resolve(spec, opts, find_landmarks)
        slug = "".join(c if c.isalnum() else "_" for c in name.lower()).strip("_") + "_" + args.view
        config = RenderConfig(width=400 * args.scale, height=300 * args.scale, view=args.view)
        mr = mouth_renderer(head, find_landmarks, config)
        if mr is None:
            print(f"{name}: no landmarks, no close-up", file=sys.stderr)
            continue
        tiles, id_tiles, back_tiles, ids = [], [], [], []
        t = np.asarray(head.rig.triangles, dtype=np.int64)
        n_cavity = int(head.rig.meta.get("mouth_cavity", 0) or 0)
        cavity = (t >= len(head.rig.neutral) - n_cavity).any(axis=1)
        with mr as r:
            for label, p in poses.items():
                v = head.rig.deformed(np.array(p))
                img = Image.fromarray(r.render(v))
                ImageDraw.Draw(img).text((6, 6), label, fill=(255, 255, 255))
                tiles.append(np.asarray(img))
                if args.ids:
                    fid = face_ids(r, v)
                    ids.append(fid)
                    pic = Image.fromarray(id_picture(fid))
                    ImageDraw.Draw(pic).text((6, 6), label, fill=(255, 255, 255))
                    id_tiles.append(np.asarray(pic))
                    back = back_faces(r, np.asarray(head.rig.neutral), v, t) & ~cavity
                    tint = (fid >= 0) & back[np.maximum(fid, 0)]
                    red = np.asarray(img).copy()
                    red[tint] = (0.5 * red[tint] + [127, 0, 0]).astype(np.uint8)
                    back_tiles.append(red)
        Image.fromarray(np.hstack(tiles)).save(args.out / f"{slug}.png")
        if args.ids:
            Image.fromarray(np.hstack(id_tiles)).save(args.out / f"{slug}_ids.png")
            Image.fromarray(np.hstack(back_tiles)).save(args.out / f"{slug}_backs.png")
            np.savez_compressed(args.out / f"{slug}_ids.npz", ids=np.stack(ids), poses=np.array(list(poses.values())))
        print(f"{name}: {args.out / slug}.png", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
