"""``facecast rig HEAD -o RIG.npz``: rig a head mesh for the four mouth parameters (paper Sec. 5)."""

from __future__ import annotations

import argparse
import time
from collections.abc import Mapping
from shlex import quote


def add_parser(sub: argparse._SubParsersAction) -> None:
    from facecast.cli import HelpFormatter

    p = sub.add_parser(
        "rig",
        help="rig a head mesh (glb/obj/ply, or 'builtin') and write a rig file plus a control-point PNG",
        formatter_class=HelpFormatter,
        description=(
            "Places the simple face model on the head from named landmarks, projects its vertices to\n"
            "control points (with the geodesic check) and precomputes the interpolation weights.\n"
            "Heads whose lips are one closed surface are cut open along the mouth line."
        ),
    )
    p.add_argument("head", help="head mesh file (.glb/.gltf/.vrm/.obj/.ply) or 'builtin' for the default head")
    p.add_argument(
        "--landmarks",
        help="landmarks JSON (name -> vertex index or [x, y, z]); default: the shipped file for known heads",
    )
    p.add_argument(
        "--head-part",
        action="append",
        default=[],
        metavar="MESH",
        help="another mesh file of the same head (eyes, teeth, tongue); repeatable (docs/animation.md)",
    )
    p.add_argument("-o", "--output", help="rig file to write (.npz); not written when the rig fails its checks")
    p.add_argument("--png", help="control-point picture to write (default: OUTPUT with suffix .png)")
    p.add_argument(
        "--simple",
        help="Candide-3 .wfm file to use as the simple face model (the paper's choice); default: the model "
        "derived from the built-in head",
    )
    p.add_argument(
        "--method",
        choices=("harmonic", "sec5", "rbf"),
        default="harmonic",
        help="deformation: the region paper 000 Sec. 5 moves with a harmonic field inside it (what every other "
        "command rigs a mesh with), plain Sec. 5 interpolation, or RBF (paper 001)",
    )
    p.add_argument("--projection", choices=("frontal", "uv"), default="frontal", help="2D projection for eq. 8-9")
    p.add_argument("--beta", type=float, default=0.5, help="gain of eq. 10 for vertices outside every triangle")
    p.add_argument(
        "--normalize-fallback", action="store_true", help="eq. 10 as a weighted mean (smoother; use with --beta 1)"
    )
    p.add_argument(
        "--keep-failing",
        action="store_true",
        help="write the rig even when it fails the extreme-pose checks (flipped triangles, edge stretch, "
        "lip interpenetration, lip gap at closure, teeth ahead of the lips)",
    )
    p.add_argument(
        "--show-landmarks",
        metavar="PNG",
        default=None,
        help="write a picture of the head with its landmarks (numbered, named); without -o, only that",
    )
    p.add_argument(
        "--save-landmarks",
        metavar="JSON",
        default=None,
        help="write the landmarks the rig was made from (found automatically, shipped or given) as a --landmarks "
        "file, to correct a point and rig again with --landmarks; without -o, those --show-landmarks draws",
    )
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from assets.errors import MeshError, RigCheckError, RigFileError
    from assets.heads.builtin import load_builtin_head
    from assets.heads.head import (
        builtin_morph_head,
        cached_rig,
        head_landmarks,
        keep_rig,
        rig_cache_path,
        rig_checked,
    )
    from assets.heads.landmarks import FoundLandmarks, credit_for, read_landmarks, write_landmarks
    from assets.heads.mesh import load_mesh
    from assets.heads.plot import plot_control_points
    from assets.heads.rigfile import save_rig
    from assets.heads.rigging import candide_face, resolve_landmarks
    from clients.render.landmarks import find_landmarks
    from realtime_core.face import RigConfig
    from realtime_core.face.checks import EXPRESSION_POSES, EXTREME_POSES

    if not args.output and not args.show_landmarks and not args.save_landmarks:
        raise SystemExit("facecast rig: error: give -o RIG.npz (or --show-landmarks PNG, --save-landmarks JSON)")
    if args.output and Path(args.output).suffix.lower() != ".npz":
        # --head takes a rig by its suffix: any other name would make the file unusable (and rigging takes minutes)
        raise RigFileError(f"{args.output}: a rig file is written as .npz; give a name ending in .npz")
    from assets.files import check_writable
    from assets.heads.plot import check_picture_path

    for picture in (args.show_landmarks, args.png):
        if picture:
            check_writable(check_picture_path(picture))
    for path in (args.output, args.save_landmarks):  # a folder that cannot be made fails now, not after the rigging
        if path:
            check_writable(path)
    cfg = RigConfig(
        method=args.method, projection_2d=args.projection, beta=args.beta, normalize_fallback=args.normalize_fallback
    )
    if Path(args.head).suffix.lower() == ".wfm":
        raise MeshError(
            f"{args.head}: a Candide-3 model needs no rig: it is driven by its own animation units; "
            "give it as --head to render, animate, say or serve"
        )
    head = load_builtin_head()
    if args.head == "builtin":
        if args.head_part:
            raise MeshError("builtin: --head-part adds meshes to a head mesh file, not to the built-in head")
        mesh = builtin_morph_head().mesh  # with its parts (teeth) for the checks
        spec: Mapping[str, object] | None = read_landmarks(args.landmarks) if args.landmarks else None
        source = args.landmarks or "builtin"
    else:
        mesh = load_mesh(args.head, parts=tuple(args.head_part))
        spec, source = head_landmarks(mesh, args.landmarks, find_landmarks)

    def save_landmarks(used: Mapping[str, object]) -> None:
        out = write_landmarks(args.save_landmarks, used, head=Path(args.head).name, source=source)
        print(f"rig: landmarks {out} (correct a point there, then rig with --landmarks {quote(str(out))})")

    if args.save_landmarks and not args.output:  # without a rig: the landmarks it would start from
        save_landmarks(spec if spec is not None else head.landmarks)
    if args.show_landmarks:
        from assets.heads.plot import plot_landmarks

        pts = resolve_landmarks(
            spec if spec is not None else dict(head.landmarks), mesh.vertices, source, mesh.triangles
        )
        out = plot_landmarks(mesh, pts, args.show_landmarks, title=f"{Path(args.head).name}: landmarks ({source})")
        print(f"rig: landmarks picture {out}")
    if not args.output:
        return 0  # only the picture or the landmarks were asked for; with -o the rig is made too
    simple = None
    if args.simple:
        from assets.heads.wfm import read_wfm

        simple = candide_face(read_wfm(args.simple))
    # With the options --head MESH uses, the rig is the one the rig cache keeps for it (--head MESH made it, or an
    # earlier `rig`): read, not made again (minutes for a scanned head); otherwise made and kept there.
    cached = args.head != "builtin" and simple is None and cfg == RigConfig()
    cache_path = rig_cache_path(mesh, args.landmarks, cfg, find_landmarks) if cached else None
    kept = cached_rig(cache_path, mesh.name) if cache_path is not None else None
    if kept is not None:
        rig, rigged, report = kept
        print(f"rig: the rig of {args.head} with these landmarks and options, read from the rig cache ({cache_path})")
    else:
        start = time.monotonic()

        def progress(line: str) -> None:  # rigging a scan takes seconds to minutes: say which way it is trying
            print(f"rig: {line} ({time.monotonic() - start:.0f} s)", flush=True)

        rig, rigged, report = rig_checked(
            mesh, spec, landmark_source=source, config=cfg, head=head, simple=simple, progress=progress
        )
        print(f"rig: made in {time.monotonic() - start:.0f} s")
    print(
        f"rig checks at {len(EXTREME_POSES)} speech poses and closure ({len(EXPRESSION_POSES)} under expressions):"
        f" {report.summary()}"
    )
    if not report.passed and not args.keep_failing:
        raise RigCheckError(
            f"{args.head}: the rig fails its checks ({'; '.join(report.failures)}); nothing written. "
            "Check the landmarks (--show-landmarks PNG), or write it anyway with --keep-failing"
        )
    out = save_rig(rig, rigged, args.output)
    if args.save_landmarks:
        # the set the rig was made from: an automatic finder's alternative when the first set's rigs all failed
        n = rig.meta.get("landmark_set")
        used = spec.alternatives[n - 1] if n and isinstance(spec, FoundLandmarks) else spec
        save_landmarks(used if used is not None else head.landmarks)
    if cache_path is not None and kept is None:
        # What --head MESH (say, render, serve) would rig from the same mesh, landmarks and options: kept in its rig
        # cache too, so the next command reads it instead of rigging the head again.
        keep_rig(rig, rigged, cache_path)
    png = Path(args.png) if args.png else Path(args.output).with_suffix(".png")
    credit = credit_for(args.head)
    from clients.errors import RenderError
    from clients.render.renderer import RenderConfig, renderer_for_rig

    image = pixels = None
    try:  # like the paper's Fig. 5: the control points over a render of the head
        with renderer_for_rig(rig, rigged, RenderConfig(width=800, height=800)) as r:
            image = r.render()
            pixels = r.project(rig.neutral[rig.control])
    except RenderError as exc:
        print(f"rig: no render for the picture ({exc}); plotting vertices instead")
    plot_control_points(
        rig,
        png,
        title=f"{Path(args.head).name}: {len(rig.control)} control points",
        credit=credit,
        image=image,
        pixels=pixels,
    )
    m = rig.meta
    print(
        f"rig {out}: {len(rig.neutral)} vertices, {len(rig.moving)} moving, {len(rig.control)} control points, "
        # "bad triangles" read as a fault of the mesh next to "flipped triangles 0 ... PASS": they are the simple face's
        # triangles whose control points the geodesic check (Sec. 5) could not join along the head's surface
        f"{m.get('replacements', 0)} geodesic replacements, "
        f"{m.get('bad_triangles', 0)} simple-face triangles not joined along the surface (Sec. 5 geodesic check), "
        f"lip seam cut: {m.get('lip_seam_cut', 0)} vertices; picture {png}"
    )
    # Options to copy into a shell: a path with a space was printed bare, and pasted back it split in two.
    same = (
        f"--head {quote(str(args.head))}"
        + "".join(f" --head-part {quote(str(q))}" for q in args.head_part)
        + (f" --landmarks {quote(str(args.landmarks))}" if args.landmarks else "")
        + (" --head-mode retarget" if mesh.targets else "")  # else its own morph targets drive it
    )
    again = (
        f"{same} reads this rig from the cache"
        if cached
        else f"{same} rigs it again (--simple and rig options other than the defaults are only in the file)"
    )
    print(
        f"rig: use it as --head {quote(str(out))} (every command; serve --rig {quote(str(out))} too)"
        + (f"; {again}" if args.head != "builtin" else "")
    )
    return 0
