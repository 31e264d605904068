"""Head renderer on moderngl: one lit, anti-aliased RGB frame per call.

Headless by default: ``moderngl.create_standalone_context(backend="egl")`` (Mesa llvmpipe when
there is no GPU). Shading: Blinn-Phong per vertex with a key, a fill and a rim light on the texture
(or the vertex colours, or a skin tone); normals are the frame's own (:meth:`HeadRenderer.normals`:
with the neutral pose's, a face the mouth turns kept the light of where it faced at rest: a ledge turned to
the viewer stayed dark, the inside of the opened mouth stayed lit), smooth across texture seams (given
``parted``, as :func:`renderer_for_rig` gives it); back faces are drawn
dark so a cut-open mouth shows a dark cavity. Anti-aliasing by multisampling (``samples``), resolved
into a plain framebuffer before reading. The camera looks along the face frame's -z at the face
centre (front) or from 35 degrees to the face's left (three-quarter).
"""

from __future__ import annotations

import io
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from assets.heads.mesh import CUTOUT_ALPHA, SKIN_COLOR, HeadMesh, part_seams, texture_cutout, vertex_normals
from clients.errors import RenderError

SEAM_SMOOTH_ANGLE = 60.0
"""Degrees: texture-seam twins share one normal only when their own normals (each from its own triangles) lie
within this angle (median 12 degrees on the scans' seams; a seam along a fold keeps its crease)."""
OPEN_POSE = (0.0, 0.0, 0.35, 0.0)
"""Mouth parameters (IOD) at which :func:`renderer_for_rig` tells a lip split from a texture seam: a lip split's
copies (a rig's cut, a model's own mouth opening, Candide-3's lips) part there, texture twins never part."""


# Lighting is evaluated per vertex (Gouraud): on llvmpipe the fragment stage dominates and a
# per-pixel Blinn-Phong doubled the draw time; at 640x480 on a ~10k-vertex head the difference
# is hard to see.
_VS = """
#version 330
uniform mat4 mvp;
uniform vec3 eye;
uniform vec3 key_dir;
uniform vec3 fill_dir;
uniform vec3 rim_dir;
in vec3 in_pos;
in vec3 in_normal;
in vec3 in_color;
in vec2 in_uv;
out vec3 v_color;
out vec2 v_uv;
out vec3 v_light;
out vec3 v_spec;
void main() {
    vec3 n = normalize(in_normal);
    vec3 v = normalize(eye - in_pos);
    float key = max(dot(n, key_dir), 0.0);
    float fill = max(dot(n, fill_dir), 0.0);
    float rim = pow(1.0 - max(dot(n, v), 0.0), 3.0) * max(dot(n, rim_dir), 0.0);
    float spec = pow(max(dot(n, normalize(key_dir + v)), 0.0), 40.0) * 0.18;
    v_light = vec3(0.24 + 0.78 * key + 0.25 * fill);
    v_spec = vec3(spec + 0.25 * rim);
    v_color = in_color;
    v_uv = in_uv;
    gl_Position = mvp * vec4(in_pos, 1.0);
}
"""

_FS = """
#version 330
uniform sampler2D tex;
uniform bool use_tex;
uniform float cutout;
in vec3 v_color;
in vec2 v_uv;
in vec3 v_light;
in vec3 v_spec;
out vec4 f_color;
void main() {
    vec4 texel = use_tex ? texture(tex, v_uv) * vec4(v_color, 1.0) : vec4(v_color, 1.0);
    // A see-through material's texels (eyelashes, a cornea; assets.heads.mesh.CUTOUT_ALPHA): not drawn.
    if (texel.a < cutout) discard;
    vec3 base = texel.rgb;
    // Back faces (the inside of a cut-open mouth) are drawn dark.
    f_color = gl_FrontFacing ? vec4(base * v_light + v_spec, 1.0) : vec4(base * 0.08 + vec3(0.05, 0.01, 0.01), 1.0);
}
"""

SKIN = SKIN_COLOR


@dataclass(frozen=True)
class RenderConfig:
    """width/height in pixels; view: "front" or "three_quarter"; samples: MSAA samples (0 = none);
    fov: vertical field of view in degrees; margin: framing around the face (1 = the face box);
    background: RGB in [0, 1]; backend: moderngl standalone backend ("egl" headless, None = default);
    lighting: "studio" (the key light above and to the face's left, the fill from its right) or "frontal" (key
    above the camera, fill from it, rim above behind: mirror-symmetric, so the render of a head mirrored left to
    right is the render of the head mirrored; the automatic landmarks' renders, clients/render/landmarks.py)."""

    width: int = 640
    height: int = 480
    view: Literal["front", "three_quarter"] = "front"
    samples: int = 4
    fov: float = 25.0
    margin: float = 1.7
    background: tuple[float, float, float] = (0.16, 0.17, 0.20)
    backend: str | None = "egl"
    lighting: Literal["studio", "frontal"] = "studio"

    def __post_init__(self) -> None:
        if not (16 <= self.width <= 8192 and 16 <= self.height <= 8192):
            raise RenderError(f"image size {self.width}x{self.height} out of range")
        if self.view not in ("front", "three_quarter"):
            raise RenderError(f"view must be 'front' or 'three_quarter', got {self.view!r}")
        if self.samples not in (0, 2, 4, 8, 16):
            raise RenderError(f"samples must be 0, 2, 4, 8 or 16, got {self.samples}")
        if self.lighting not in ("studio", "frontal"):
            raise RenderError(f"lighting must be 'studio' or 'frontal', got {self.lighting!r}")


def _look_at(eye: np.ndarray, target: np.ndarray, up: np.ndarray) -> np.ndarray:
    f = target - eye
    f /= np.linalg.norm(f)
    s = np.cross(f, up)
    s /= np.linalg.norm(s)
    u = np.cross(s, f)
    m = np.eye(4)
    m[0, :3], m[1, :3], m[2, :3] = s, u, -f
    m[:3, 3] = -m[:3, :3] @ eye
    return m


def _perspective(fov_deg: float, aspect: float, near: float, far: float) -> np.ndarray:
    f = 1.0 / np.tan(np.radians(fov_deg) / 2)
    m = np.zeros((4, 4))
    m[0, 0], m[1, 1] = f / aspect, f
    m[2, 2], m[2, 3] = (far + near) / (near - far), 2 * far * near / (near - far)
    m[3, 2] = -1.0
    return m


class HeadRenderer:
    """Renders a head mesh with given vertex positions. Not thread-safe; call :meth:`close`.

    mesh: the head (its vertices are the neutral pose); axes (3, 3) rows x (face's left), y (up),
    z (out of the face) and centre (3,), size (face height, mesh units) frame the camera.
    parted: None, or (n, 3) the head's vertices with the mouth open (:func:`renderer_for_rig` passes the rig's at
    OPEN_POSE): vertices that coincide at rest and still coincide there are texture-seam twins and share one
    normal (SEAM_SMOOTH_ANGLE). Without it every vertex keeps its own: at rest a lip split (whose copies must
    keep the closed lips' line) and a texture seam look alike.
    """

    def __init__(
        self,
        mesh: HeadMesh,
        *,
        centre: np.ndarray,
        axes: np.ndarray,
        size: float,
        config: RenderConfig = RenderConfig(),
        parted: np.ndarray | None = None,
    ) -> None:
        try:
            import moderngl
        except ImportError as exc:
            raise RenderError(f"moderngl is not installed: {exc}") from exc
        self.config = config
        try:
            kw: dict[str, Any] = {"backend": config.backend} if config.backend else {}
            self.ctx = moderngl.create_standalone_context(require=330, **kw)
        except Exception as exc:  # glcontext raises bare Exception when EGL is missing
            raise RenderError(f"cannot create an OpenGL 3.3 context (backend={config.backend}): {exc}") from exc
        ctx = self.ctx
        v = np.asarray(mesh.vertices, dtype=np.float32)
        t = np.asarray(mesh.triangles, dtype=np.int32)
        self.n = len(v)
        self._triangles = t
        # A head exported as several meshes shades as one surface across their seams (vertex_normals' part).
        self._seams = None if mesh.part is None else part_seams(v, mesh.part)  # found once, at rest
        self._owner = None if parted is None else _seam_owner(v, t, parted, tolerance=1e-6 * size)
        normals = self.normals(v)
        textured = mesh.texture is not None and mesh.uvs is not None
        # A textured head's colours multiply its texture (glTF's COLOR_0; a textured head's teeth shaded by their
        # depth in the mouth, assets.heads.cavity.with_dark_mouth_inside): white when it has none.
        blank = (1.0, 1.0, 1.0) if textured else SKIN
        colors = (
            np.asarray(mesh.colors, dtype=np.float32)
            if mesh.colors is not None
            else np.tile(np.asarray(blank, dtype=np.float32), (self.n, 1))
        )
        uvs = np.asarray(mesh.uvs, dtype=np.float32) if mesh.uvs is not None else np.zeros((self.n, 2), np.float32)
        self.prog = ctx.program(vertex_shader=_VS, fragment_shader=_FS)
        self.pos_buf = ctx.buffer(v.tobytes(), dynamic=True)
        self.normal_buf = ctx.buffer(normals.tobytes(), dynamic=True)
        static = np.hstack([colors, uvs]).astype(np.float32)
        self.static_buf = ctx.buffer(static.tobytes())
        self.ibo = ctx.buffer(t.tobytes())
        self.vao = ctx.vertex_array(
            self.prog,
            [
                (self.pos_buf, "3f", "in_pos"),
                (self.normal_buf, "3f", "in_normal"),
                (self.static_buf, "3f 2f", "in_color", "in_uv"),
            ],
            index_buffer=self.ibo,
        )
        self.texture = None
        use_tex = mesh.texture is not None and mesh.uvs is not None
        if use_tex and mesh.texture is not None:
            from PIL import Image

            try:
                # Rows go up as stored: texture row 0 is v = 0 (checked on the Lee Perry-Smith head).
                cut = texture_cutout(mesh.texture)
                img = Image.open(io.BytesIO(mesh.texture)).convert("RGBA" if cut else "RGB")
            except Exception as exc:  # PIL raises several types for corrupt images
                raise RenderError(f"{mesh.name}: cannot decode texture: {exc}") from exc
            self.texture = ctx.texture(img.size, 4 if cut else 3, img.tobytes())
            self.prog["cutout"].value = CUTOUT_ALPHA if cut else 0.0
            self.texture.build_mipmaps()
            if cut:
                # Averaged, thin strands' coverage fell under the cut-off at a distance: eyelash cards drew as flecks.
                for level, data in enumerate(cutout_levels(np.asarray(img)), start=1):
                    self.texture.write(data.tobytes(), level=level)
            self.texture.use(0)
            self.prog["tex"].value = 0
        self.prog["use_tex"].value = bool(use_tex)
        w, h = config.width, config.height
        self.fbo_ms: moderngl.Framebuffer | None
        if config.samples:
            self.fbo_ms = ctx.framebuffer(
                color_attachments=[ctx.renderbuffer((w, h), 4, samples=config.samples)],
                depth_attachment=ctx.depth_renderbuffer((w, h), samples=config.samples),
            )
            self.fbo = ctx.framebuffer(color_attachments=[ctx.renderbuffer((w, h), 4)])
        else:
            self.fbo_ms = None
            self.fbo = ctx.framebuffer(
                color_attachments=[ctx.renderbuffer((w, h), 4)], depth_attachment=ctx.depth_renderbuffer((w, h))
            )
        # Camera from the face frame.
        ax = np.asarray(axes, dtype=np.float64)
        x, y, z = ax
        if config.view == "three_quarter":
            a = np.radians(35.0)
            z = np.cos(a) * z + np.sin(a) * x
        dist = config.margin * size / (2 * np.tan(np.radians(config.fov) / 2))
        c = np.asarray(centre, dtype=np.float64)
        eye = c + dist * z
        view = _look_at(eye, c, y)
        proj = _perspective(config.fov, w / h, dist * 0.05, dist * 10)
        self.mvp = proj @ view
        self.prog["mvp"].write(self.mvp.T.astype(np.float32).tobytes())
        self.prog["eye"].value = tuple(float(x) for x in eye)
        side = 0.0 if config.lighting == "frontal" else 1.0  # frontal: no light from either side
        key = 0.55 * ax[2] + 0.45 * ax[1] + side * 0.45 * ax[0]
        fill = 0.8 * ax[2] - side * 0.6 * ax[0]
        rim = -0.5 * ax[2] + 0.6 * ax[1] - side * 0.6 * ax[0]
        for name, d in (("key_dir", key), ("fill_dir", fill), ("rim_dir", rim)):
            self.prog[name].value = tuple(d / np.linalg.norm(d))
        self._out = np.empty((h, w, 3), dtype=np.uint8)

    def render(self, vertices: np.ndarray | None = None) -> np.ndarray:
        """One frame (height, width, 3) uint8 RGB, top row first, for vertices (n, 3) (None: unchanged)."""
        if vertices is not None:
            v = np.ascontiguousarray(vertices, dtype=np.float32)
            if v.shape != (self.n, 3):
                raise RenderError(f"vertices must be ({self.n}, 3), got {v.shape}")
            self.pos_buf.write(v)
            self.normal_buf.write(self.normals(v))
        import moderngl

        target = self.fbo_ms or self.fbo
        target.use()
        bg = self.config.background
        target.clear(bg[0], bg[1], bg[2], 1.0, depth=1.0)
        self.ctx.enable(moderngl.DEPTH_TEST)
        self.ctx.disable(moderngl.CULL_FACE)
        self.vao.render(moderngl.TRIANGLES)
        if self.fbo_ms is not None:
            self.ctx.copy_framebuffer(self.fbo, self.fbo_ms)
        raw = self.fbo.read(components=3, alignment=1)
        h, w = self.config.height, self.config.width
        self._out[:] = np.frombuffer(raw, dtype=np.uint8).reshape(h, w, 3)[::-1]
        return self._out.copy()

    def normals(self, vertices: np.ndarray) -> np.ndarray:
        """(n, 3) float32 unit vertex normals of the head at ``vertices`` (n, 3): area-weighted over the frame's
        own triangles, one normal for each group of texture-seam twins (see ``parted``)."""
        return vertex_normals(
            np.asarray(vertices, dtype=np.float32), self._triangles, together=self._owner, seams=self._seams
        )

    def project(self, points: np.ndarray) -> np.ndarray:
        """Pixel coordinates (k, 2) (column, row from the top) of 3D points (k, 3)."""
        p = np.c_[np.asarray(points, dtype=np.float64), np.ones(len(points))] @ self.mvp.T
        ndc = p[:, :2] / p[:, 3:4]
        return np.c_[(ndc[:, 0] + 1) / 2 * self.config.width, (1 - ndc[:, 1]) / 2 * self.config.height]

    def close(self) -> None:
        self.ctx.release()

    def __enter__(self) -> HeadRenderer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def cutout_levels(rgba: np.ndarray, cut: float = CUTOUT_ALPHA) -> list[np.ndarray]:
    """The mip levels below ``rgba`` (h, w, 4) uint8, a texture whose alpha is cut at ``cut`` (coverage 0 or 1), each
    (max(1, h >> k), max(1, w >> k), 4) uint8 for k = 1, 2, ... down to 1 x 1 (OpenGL's chain). Colour is averaged
    over the covered texels only; alpha is averaged, then scaled by the one factor per level that brings the share
    of texels at or over ``cut`` closest to the full texture's (coverage-preserving mipmaps, Castano 2010), never
    under 1 (an opaque texel stays opaque): a plain average turns a comb of thin strands (an eyelash card's tips, 3
    texels in 10) into alpha under the cut-off a few levels down, and the strands vanish or break into flecks at a
    distance (the Character Creator held-out head's lashes)."""
    from PIL import Image

    a0 = rgba[..., 3].astype(np.float64) / 255.0
    share = float((a0 >= cut).mean())
    covered = rgba[..., :3].astype(np.float64) * a0[..., None]
    h, w = a0.shape
    out: list[np.ndarray] = []
    k = 1
    while (h >> (k - 1)) > 1 or (w >> (k - 1)) > 1:
        size = (max(1, w >> k), max(1, h >> k))

        def shrunk(x: np.ndarray, size: tuple[int, int] = size) -> np.ndarray:
            return np.asarray(Image.fromarray(x.astype(np.float32), "F").resize(size, Image.Resampling.BOX))

        a = shrunk(a0)
        rgb = np.stack([shrunk(covered[..., c]) for c in range(3)], axis=-1) / np.maximum(a, 1e-6)[..., None]
        # Factors from 1 (alpha only ever raised: an opaque texel stays opaque) to one that covers every texel.
        lo, hi = 1.0, 64.0 / max(float(a.max()), 1e-6)

        def share_at(f: float, a: np.ndarray = a) -> float:
            return float((np.minimum(a * f, 1.0) >= cut).mean())

        for _ in range(30):  # the smallest factor whose share covered reaches the full texture's, and the one below
            mid = 0.5 * (lo + hi)
            lo, hi = (lo, mid) if share_at(mid) >= share else (mid, hi)
        # Whichever comes closer: a level whose texels all hold the same part of a strand is all or nothing, and a
        # comb 0.375 covered drawn as a solid block is further from it than drawn as nothing.
        f = hi if abs(share_at(hi) - share) <= abs(share_at(lo) - share) else lo
        level = np.empty((size[1], size[0], 4), np.uint8)
        level[..., :3] = np.clip(np.round(rgb), 0, 255)
        level[..., 3] = np.clip(np.round(np.minimum(a * f, 1.0) * 255), 0, 255)
        out.append(level)
        k += 1
    return out


def _seam_owner(rest: np.ndarray, triangles: np.ndarray, parted: np.ndarray, *, tolerance: float) -> np.ndarray:
    """(n,) int: each vertex's lowest-index texture-seam twin (itself when it has none): the vertices that coincide
    at ``rest`` (n, 3), still coincide (within ``tolerance``) at ``parted`` (n, 3), and whose own normals at rest
    lie within SEAM_SMOOTH_ANGLE of the group's first vertex's."""
    # Imported here: the package loads the rig stack, which a viewer drawing streamed frames never needs.
    from realtime_core.face.welding import weld

    canon, _ = weld(np.asarray(rest, dtype=np.float64))
    n = len(canon)
    first = np.full(canon.max(initial=-1) + 1, n)
    np.minimum.at(first, canon, np.arange(n))
    head = first[canon]
    own = vertex_normals(rest, triangles)
    p = np.asarray(parted, dtype=np.float64)
    twin = (np.linalg.norm(p - p[head], axis=1) <= tolerance) & (
        (own * own[head]).sum(axis=1) >= np.cos(np.radians(SEAM_SMOOTH_ANGLE))
    )
    return np.where(twin, head, np.arange(n))


def renderer_for_rig(rig, mesh: HeadMesh, config: RenderConfig = RenderConfig()) -> HeadRenderer:
    """A renderer framed on the rig's face: a Sec. 5 rig's placed simple model gives the face box
    and frame; a MorphRig's landmarks (when known) or the box of the vertices its targets move."""
    from assets.heads.rigging import mouth_landmarks
    from realtime_core.face import face_frame

    slm = rig.meta.get("simple_landmarks")
    simple = getattr(rig, "simple", None)
    if simple is not None:
        sv = simple.vertices
        fr = face_frame(sv, mouth_landmarks(slm)) if slm else None
    else:
        lm = rig.meta.get("landmarks")
        pts = np.asarray(rig.neutral, dtype=np.float64)[rig.moving] if len(rig.moving) else np.asarray(rig.neutral)
        fr = None
        if lm:
            names = list(lm)
            pv = np.array([lm[k] for k in names], dtype=np.float64)
            fr = face_frame(pv, mouth_landmarks({k: i for i, k in enumerate(names)}))
        sv = pts
        if fr is None:
            # Unknown face frame: glTF's convention (+y up, face towards +z). Frame the face from the
            # vertices the driven targets move most (> 10% of the largest displacement: lips, jaw,
            # chin; a body, hair or props never move), whatever else the file holds (a full-body
            # avatar). Their width W is about the jaw's; the ratios reproduce the landmark framing
            # below on the built-in head (size 1.24 W, centre 0.125 W above their top, 0.56 W behind
            # their front).
            # Speech's targets only: a head's face shapes (brows, eyes: MorphRig.n_face, last) moved the box up to
            # the brows and framed an ARKit head without landmarks with its mouth at the picture's bottom edge.
            targets = getattr(rig, "targets", None)
            big = np.ones(len(pts), dtype=bool)
            if targets is not None and len(rig.moving):
                speech = np.asarray(targets)[: len(targets) - getattr(rig, "n_face", 0)]
                mag = np.abs(speech).max(axis=(0, 2))
                big = mag > 0.1 * max(float(mag.max()), 1e-30)
            lo, hi = pts[big].min(0), pts[big].max(0)
            w = float(max(hi[0] - lo[0], 1e-9))
            centre = np.array([0.5 * (lo[0] + hi[0]), hi[1] + 0.125 * w, hi[2] - 0.56 * w])
            return HeadRenderer(
                mesh, centre=centre, axes=np.eye(3), size=1.24 * w, config=config, parted=parted_for(rig)
            )
    axes = fr.axes if fr is not None else np.eye(3)
    q = (sv - sv.mean(0)) @ axes.T
    size = float(max(np.ptp(q[:, 1]), np.ptp(q[:, 0]) * config.height / config.width))
    centre = sv.mean(0)
    if fr is not None and simple is None:
        # Landmarks of a morph head: the face spans about 2.6 IOD high around the eyes-mouth middle.
        size = 2.6 * fr.iod
        centre = fr.origin - 0.45 * fr.iod * axes[1]
    if fr is not None:
        # Pivot inside the head (a turned view stays framed) and a little up (the skull shows).
        centre = centre - 0.5 * fr.iod * axes[2] + 0.35 * fr.iod * axes[1]
    return HeadRenderer(mesh, centre=centre, axes=axes, size=size, config=config, parted=parted_for(rig))


def parted_for(rig) -> np.ndarray:
    """(n, 3) the rig's head with the mouth open (OPEN_POSE): :class:`HeadRenderer`'s ``parted``."""
    return np.asarray(rig.deformed(np.asarray(OPEN_POSE, dtype=np.float64)), dtype=np.float64)
