"""Animation benchmarks (prints figures, asserts nothing): rig application and offline rendering.

    python -m benchmarks.render [--frames 200] [--quick] [--retarget]

1. Per-frame cost of applying a rig, ``rig.displacements(params)`` (one (n_s*3, 4) product and one
   CSR product), for the built-in head and for a synthetic 10,000-vertex rig with the same
   structure (3 control points per vertex); median and 99th percentile in microseconds.
2. Frames per second of the moderngl renderer at 640x480 for the built-in head (deform + upload +
   draw + MSAA resolve + read-back), for 0, 2 and 4 MSAA samples.
3. With --retarget: retargeting the simple model onto its own source (the built-in head): relative
   RMS error of each mouth unit against the head's native ARKit target, over the vertices the target
   moves, for Sec. 5 (paper eq. 10 with beta 0.5, and normalised with beta 1) and for the RBF map.
BLAS is pinned to one thread (threadpoolctl) as in the server.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import scipy.sparse as sp


def _percentiles(samples_s: list[float]) -> tuple[float, float]:
    a = np.asarray(samples_s) * 1e6
    return float(np.median(a)), float(np.percentile(a, 99))


def time_rig(rig, n: int) -> tuple[float, float]:
    """Median and p99 (us) of rig.displacements over n random parameter vectors."""
    rng = np.random.default_rng(0)
    ps = rng.normal(scale=0.05, size=(n, 4)).astype(np.float32)
    for p in ps[:20]:
        rig.displacements(p)
    out = []
    for p in ps:
        t = time.perf_counter()
        rig.displacements(p)
        out.append(time.perf_counter() - t)
    return _percentiles(out)


def synthetic_rig(n_head: int = 10_000, n_simple: int = 220):
    """A Rig with n_head moving vertices, each following 3 random control points (Sec. 5 structure)."""
    from realtime_core.face import FaceModel, MouthCalibration, Rig

    rng = np.random.default_rng(1)
    cols = np.stack([rng.choice(n_simple, 3, replace=False) for _ in range(n_head)])
    w = rng.dirichlet(np.ones(3), size=n_head)
    g = sp.csr_matrix((w.ravel(), (np.repeat(np.arange(n_head), 3), cols.ravel())), shape=(n_head, n_simple))
    simple = FaceModel(vertices=rng.normal(size=(n_simple, 3)), triangles=np.zeros((0, 3), int), name="synthetic")
    cal = MouthCalibration(groups=(("a",), ("b",), ("c",), ("d",)), response=np.eye(4), matrix=np.eye(4))
    return Rig(
        neutral=rng.normal(size=(n_head, 3)).astype(np.float32),
        triangles=np.zeros((0, 3), np.int32),
        moving=np.arange(n_head),
        matrix=sp.kron(g, sp.identity(3), format="csr"),
        basis=rng.normal(size=(n_simple * 3, 4)),
        control=np.arange(n_simple),
        simple=simple,
        calibration=cal,
    )


def time_render(rig, mesh, samples: int, frames: int) -> float:
    from clients.render.renderer import RenderConfig, renderer_for_rig

    with renderer_for_rig(rig, mesh, RenderConfig(width=640, height=480, samples=samples)) as r:
        ps = np.zeros((frames, 4))
        ps[:, 2] = 0.1 * (1 + np.sin(np.arange(frames) / 3)) / 2
        r.render(rig.deformed(ps[0]))
        t = time.perf_counter()
        for p in ps:
            r.render(rig.deformed(p))
        return frames / (time.perf_counter() - t)


RETARGET_UNITS = (
    "jawOpen",
    "mouthStretchLeft",
    "mouthStretchRight",
    "mouthUpperUpLeft",
    "mouthUpperUpRight",
    "mouthFrownLeft",
    "mouthFrownRight",
    "mouthSmileLeft",
    "mouthPucker",
    "mouthFunnel",
)


def retarget_errors() -> dict[str, dict[str, float]]:
    """method -> unit -> relative RMS error |pred - native| / |native| over the target's moving vertices."""
    from assets.heads.builtin import load_builtin_head
    from assets.heads.rigging import MOUTH_GROUPS, mouth_landmarks, simple_face
    from realtime_core.face import RigConfig, face_frame
    from realtime_core.face.rig import head_weights

    h = load_builtin_head()
    s = simple_face(h)
    frame = face_frame(h.mesh.vertices, mouth_landmarks(h.landmarks))
    train = np.concatenate([s.model.animation_units[n] for g in MOUTH_GROUPS for n in g], axis=1)
    methods = {
        "sec5 (beta 0.5)": RigConfig(),
        "sec5 (normalised eq.10, beta 1)": RigConfig(beta=1.0, normalize_fallback=True),
        "rbf (paper r, GCV)": RigConfig(method="rbf"),
        "rbf (r = 0.3 IOD, GCV)": RigConfig(method="rbf", rbf_radius=0.3),
    }
    out: dict[str, dict[str, float]] = {}
    for name, cfg in methods.items():
        g, _, _ = head_weights(
            h.mesh.vertices, h.mesh.triangles, s.model, frame, config=cfg, training=train, allowed=h.part == 0
        )
        out[name] = {}
        for u in RETARGET_UNITS:
            native = h.targets[u]
            pred = g @ s.model.animation_units[u]
            m = np.linalg.norm(native, axis=1) > 1e-9
            out[name][u] = float(np.sqrt(((pred - native)[m] ** 2).sum() / (native[m] ** 2).sum()))
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames", type=int, default=200, help="frames per render measurement")
    ap.add_argument("--quick", action="store_true", help="fewer repetitions")
    ap.add_argument("--retarget", action="store_true", help="also print the retargeting error table")
    args = ap.parse_args(argv)
    from threadpoolctl import threadpool_limits

    from assets.heads.rigfile import builtin_rig

    n_rig = 2000 if args.quick else 20000
    frames = 50 if args.quick else args.frames
    with threadpool_limits(limits=1):
        rig, mesh = builtin_rig()
        print("rig application (rig.displacements, float32), goal < 100 us for 10k vertices")
        for name, r in (("built-in head", rig), ("synthetic 10k", synthetic_rig())):
            med, p99 = time_rig(r, n_rig)
            print(
                f"  {name:15s} {len(r.moving):6d} moving, nnz {r.matrix.nnz:6d}: "
                f"median {med:6.1f} us, p99 {p99:6.1f} us"
            )
        print(
            f"rendering 640x480, built-in head ({len(mesh.vertices)} vertices, {len(mesh.triangles)} triangles), "
            "goal >= 200 fps"
        )
        for s in (0, 2, 4):
            print(
                f"  MSAA {s}: {time_render(rig, mesh, s, frames):6.1f} fps "
                "(deform + upload + draw + resolve + read-back)"
            )
        if args.retarget:
            print("retargeting onto the source head: relative RMS error per unit (0 = exact, 1 = no motion)")
            for name, errs in retarget_errors().items():
                print(f"  {name}")
                print("    " + "  ".join(f"{u} {e:.2f}" for u, e in errs.items()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
