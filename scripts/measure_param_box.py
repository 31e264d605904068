"""The box of mouth parameters the shipped models really produce on real speech (the rig checks' poses).

    python scripts/measure_param_box.py [--data ../shared/data] [--grid 36] [--say 6] [--save frames.npz]

Runs every speech WAV under DATA/speech and the audio of the first --grid GRID s1 validation
sentences through the shipped default and low-latency models (the live streaming path, as `facecast
animate` runs it), plus --say sentences through `facecast say` (unit selection over GRID s1 lips), and
prints per source the range of each parameter, the joint extremes (how far speech reaches towards each
sign combination of every parameter pair, as a fraction of the box's end on each side), and the frames
that reach furthest towards each corner of the box. Then it chooses the rig checks' poses: each
parameter alone at both ends of the box or of SPEECH_POSES, whichever is further (SINGLE_POSES), and
measured frames added one at a time (the one furthest outside, rounded away from 0 to 3 decimals)
until every measured frame lies within
--tolerance IOD of the convex hull of SPEECH_POSES + SINGLE_POSES + the added frames; the added frames
are printed as the MEASURED_POSES table of realtime_core/face/checks.py, which quotes this run.
"""

from __future__ import annotations

import argparse
import itertools
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
from assets.shared import shared_data_root  # noqa: E402 (after the path: a worktree's own package)

NAMES = ("upper_lip_raise", "lip_stretch", "mouth_open", "lip_corner_depress")
SAY_TEXTS = (
    "Place blue at F two now.",
    "We were away a year ago.",
    "Who knew you would move to the zoo?",
    "I saw a large dog on the far hill.",
    "She sells sea shells by the sea shore.",
    "My mother bought me a bowl of warm soup.",
    "Please call Stella and ask her to bring these things with her from the store.",
    "Why are you always so happy in the morning?",
)


def model_frames(model_name: str, files: list[Path]) -> np.ndarray:
    """(n_frames, 4) the live path's estimate over all ``files``."""
    from assets.audio import read_audio
    from assets.modelfile import load_speech_model
    from realtime_core.pipeline import speech_to_params

    model = load_speech_model("hmm", model_name)
    out = []
    for f in files:
        samples, rate = read_audio(f)
        out.append(np.asarray(speech_to_params(model, samples, rate), dtype=np.float64)[:, :4])
    return np.concatenate(out)


def say_frames(texts: tuple[str, ...], extra: tuple[str, ...] = ()) -> np.ndarray:
    """(n_frames, 4) `facecast say` unit selection over ``texts`` (CSV output: t + 4 parameters); ``extra``: more
    `facecast say` arguments (e.g. ``("--expression", "smile")``)."""
    out = []
    exe = REPO / ".venv" / "bin" / "facecast"
    with tempfile.TemporaryDirectory() as tmp:
        for i, text in enumerate(texts):
            csv = Path(tmp) / f"say{i}.csv"
            subprocess.run(
                [str(exe), "say", text, "-o", str(csv), *extra],
                check=True,
                capture_output=True,
                env={**os.environ, "PYTHONPATH": str(REPO)},
            )
            out.append(np.loadtxt(csv, delimiter=",", skiprows=1)[:, 1:5])
    return np.concatenate(out)


def joint_reach(x: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> dict[tuple[int, int, int, int], float]:
    """(i, j, si, sj) -> max over frames of min(reach_i, reach_j), where reach is the frame's value as a
    fraction of the box's end on the side of sign s (1 = the end, 0 = the neutral 0)."""
    ends = {1: np.where(hi > 0, hi, np.inf), -1: np.where(lo < 0, -lo, np.inf)}
    res = {}
    for i, j in itertools.combinations(range(4), 2):
        for si, sj in itertools.product((1, -1), repeat=2):
            ri = np.clip(si * x[:, i] / ends[si][i], 0, None)
            rj = np.clip(sj * x[:, j] / ends[sj][j], 0, None)
            res[(i, j, si, sj)] = float(np.minimum(ri, rj).max())
    return res


def away(p: np.ndarray) -> np.ndarray:
    """p rounded to 3 decimals away from 0 (so a rounded pose lies at least as far out as the frame)."""
    return np.sign(p) * np.ceil(np.abs(p) * 1000 - 1e-9) / 1000 + 0.0


def hull_poses(x: np.ndarray, *, tolerance: float) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """(single-parameter ends, added frames) whose hull with SPEECH_POSES holds every frame of ``x`` (n, 4)
    to within ``tolerance`` (IOD, distance outside the hull's facets)."""
    from realtime_core.face.checks import SPEECH_POSES, hull_additions

    x = np.column_stack([x[:, :2], np.maximum(x[:, 2], 0.0), x[:, 3:]])  # mouth_open's floor is 0 (lips touching)
    speech = np.asarray(SPEECH_POSES, dtype=np.float64)
    singles = []
    for j in range(4):  # the ends of the measured box or of the articulatory targets, whichever is further
        for end in (min(x[:, j].min(), speech[:, j].min()), max(x[:, j].max(), speech[:, j].max())):
            if abs(end) > 1e-9:
                p = np.zeros(4)
                p[j] = away(np.array([end]))[0]
                singles.append(p)
    return singles, hull_additions(np.array(list(speech) + singles), x, tolerance=tolerance, snap=away)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=shared_data_root())
    ap.add_argument("--grid", type=int, default=36, help="GRID s1 validation sentences")
    ap.add_argument("--say", type=int, default=6, help="`facecast say` sentences")
    ap.add_argument("--tolerance", type=float, default=0.002, help="IOD a frame may lie outside the poses' hull")
    ap.add_argument("--save", type=Path, default=None, help="write every frame per source (.npz)")
    args = ap.parse_args()
    from assets.grid import split_of

    wavs = sorted((args.data / "speech").rglob("*.wav"))
    grid = sorted(p for p in (args.data / "video" / "grid_s1" / "video").glob("*.mp4") if split_of(p.stem) == "val")[
        : args.grid
    ]
    if not wavs or len(grid) < args.grid:
        raise SystemExit(f"{args.data}: no speech wavs or fewer than {args.grid} GRID s1 val sentences (give --data)")
    sources: dict[str, np.ndarray] = {}
    for model in ("default", "low-latency"):
        sources[f"{model}, speech wavs"] = model_frames(model, wavs)
        sources[f"{model}, GRID s1 val"] = model_frames(model, grid)
    if args.say:
        sources["say (unit selection)"] = say_frames(SAY_TEXTS[: args.say])
    x = np.concatenate(list(sources.values()))
    lo, hi = x.min(axis=0), x.max(axis=0)
    print(f"{len(wavs)} speech wavs, {len(grid)} GRID s1 val sentences, {min(args.say, len(SAY_TEXTS))} say texts")
    print("| source | frames | " + " | ".join(NAMES) + " |")
    print("|---|---|" + "---|" * 4)
    for name, v in {**sources, "all": x}.items():
        cells = " | ".join(f"{a:.3f}..{b:.3f}" for a, b in zip(v.min(axis=0), v.max(axis=0), strict=True))
        print(f"| {name} | {len(v)} | {cells} |")
    print("correlation (all frames):")
    print(np.array2string(np.corrcoef(x.T), precision=2))
    print("joint reach (fraction of each side's end reached together, all frames):")
    for (i, j, si, sj), r in joint_reach(x, lo, hi).items():
        print(f"  {'+' if si > 0 else '-'}{NAMES[i]:20s} {'+' if sj > 0 else '-'}{NAMES[j]:20s} {r:.2f}")
    print("furthest frame towards each corner of the box (normalised by the box's ends):")
    span = np.where(np.stack([hi, -lo]) > 0, np.stack([hi, -lo]), 1.0)
    for signs in itertools.product((1, -1), repeat=4):
        s = np.array(signs)
        norm = np.where(s > 0, x / span[0], -x / span[1])
        k = int(np.argmax(np.clip(norm, 0, None).sum(axis=1)))
        print(f"  {''.join('+' if a > 0 else '-' for a in signs)}: " + ", ".join(f"{v:.3f}" for v in x[k]))
    singles, added = hull_poses(x, tolerance=args.tolerance)
    print("SINGLE_POSES (each parameter alone at both ends of the box):")
    for p in singles:
        print("    (" + ", ".join(f"{v + 0.0:.3f}" for v in p) + "),")
    print(f"MEASURED_POSES ({len(added)} frames; every frame within {args.tolerance} IOD of the poses' hull):")
    for p in added:
        print("    (" + ", ".join(f"{v + 0.0:.3f}" for v in p) + "),")
    if args.save is not None:
        np.savez(args.save, **{k.replace(" ", "_").replace(",", ""): v for k, v in sources.items()})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
