"""How reliable is the lip_stretch target, and what limits the default model's r(lip_stretch)? (s1 val only)

    python scripts/lip_stretch_truth.py [--model default]

Issue 10 asks each mouth parameter to measure what its name says on real faces. lip_stretch is the
mouth-corner distance (MediaPipe 61-291) minus the clip's rest width (`training.params`). On the 93 val
sentences of GRID s1 (the shared extraction's cached tracks; never the test split) this prints:

1. Per width definition (the shipped corner distance; inner-lip corners 78-308; the horizontal spread of
   the 40 lip-contour points, 2 x rms of x; both widths at the clip's median pose-fit scale instead of the
   per-frame one): sd, jitter (residual of a 5-frame Savitzky-Golay fit over the sd, clip means removed),
   the share of the variance in clip offsets, and r with the shipped definition within clips.
2. The agreement of three width measures within clips and the reliability it implies, the per-frame
   pose-fit scale's drift and its share of the width's within-clip variance.
3. The rest width: the width at rest before the first word against after the last word (the shipped
   rest pose is the median over both), and the clip-offset share with each as the rest.
4. The model's val estimates of lip_stretch: r pooled, within clips (clip means removed from both), of the
   clip means, against the truth smoothed, on speech and quiet frames, and the error's spectrum.
"""

from __future__ import annotations

import argparse

import numpy as np
from scipy.signal import savgol_filter

from assets.grid import SILENCE_WORDS, read_words, sentences
from assets.modelfile import load_model, resolve_model
from realtime_core.face.registration import fit_similarity
from training import video
from training.facetrack import LIPS_INNER, LIPS_OUTER, STABLE, cache_path, read_raw
from training.reallips import evaluate_lips, s1_clips

CONTOUR = sorted(set(LIPS_OUTER) | set(LIPS_INNER))


def pose_scales(landmarks: np.ndarray, iterations: int = 3) -> np.ndarray:
    """(n,) the similarity scale of each frame's pose fit, as ``training.video.remove_head_pose`` fits it."""
    stable = list(STABLE)
    ref = landmarks[0].astype(np.float64)
    aligned = landmarks.astype(np.float64)
    scale = np.ones(len(landmarks))
    for _ in range(iterations):
        for k in range(len(landmarks)):
            s, r, t = fit_similarity(landmarks[k, stable], ref[stable])
            aligned[k] = s * landmarks[k] @ r.T + t
            scale[k] = s
        ref = aligned.mean(axis=0)
    return scale


def widths(track) -> dict[str, np.ndarray]:
    """(n_frames,) widths of one clip (IOD, minus the clip's rest value) by each definition."""
    lm = track.landmarks.astype(np.float64)
    ne = track.neutral.astype(np.float64)
    raw = read_raw(cache_path(None, track.quality["sha1"], track.sample_rate_hz))
    found = ~np.isnan(raw.video_landmarks[:, :, 0]).any(axis=1)
    scale_v = pose_scales(video._fill_gaps(raw.video_landmarks, found))
    scale = video._resample_at(raw.video_times_s, scale_v, np.arange(track.n_frames) / 30)
    rel = scale / np.median(scale)  # distances at the clip's median scale: divide by rel
    corner = np.linalg.norm(lm[:, 61] - lm[:, 291], axis=1)
    spread = 2 * lm[:, CONTOUR, 0].std(axis=1)
    corner0 = float(np.linalg.norm(ne[61] - ne[291]))
    spread0 = float(2 * ne[CONTOUR, 0].std())
    return {
        "corner (shipped)": corner - corner0,
        "inner corners": np.linalg.norm(lm[:, 78] - lm[:, 308], axis=1) - np.linalg.norm(ne[78] - ne[308]),
        "contour spread": spread - spread0,
        "corner, median scale": corner / rel - corner0,
        "contour spread, median scale": spread / rel - spread0,
        "_scale_rel": rel,
        "_corner_abs": corner,
    }


def clip_offset_share(xs: list[np.ndarray]) -> float:
    """Share of the pooled variance in the clip means (frame-weighted)."""
    pooled = np.concatenate(xs)
    means = np.array([x.mean() for x in xs])
    lens = np.array([len(x) for x in xs])
    return float(np.sum(lens * (means - pooled.mean()) ** 2) / np.sum((pooled - pooled.mean()) ** 2))


def within(xs: list[np.ndarray]) -> np.ndarray:
    return np.concatenate([x - x.mean() for x in xs])


def jitter(xs: list[np.ndarray]) -> float:
    """sd of the residual of a 5-frame quadratic Savitzky-Golay fit over the within-clip sd."""
    w = [x - x.mean() for x in xs]
    return float(np.concatenate([x - savgol_filter(x, 5, 2) for x in w]).std() / np.concatenate(w).std())


def r(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.corrcoef(a, b)[0, 1])


def band_shares(xs: list[np.ndarray]) -> list[float]:
    """Shares of the summed power below 1 Hz, 1-3 Hz and above 3 Hz (each clip's mean removed)."""
    tot = np.zeros(3)
    for x in xs:
        p = np.abs(np.fft.rfft(x - x.mean())) ** 2
        f = np.fft.rfftfreq(len(x), 1 / 30)
        tot += [p[f < 1].sum(), p[(f >= 1) & (f < 3)].sum(), p[f >= 3].sum()]
    return [round(float(v), 3) for v in tot / tot.sum()]


def main() -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--model", default="default", help="the model whose val estimates are decomposed (section 4)")
    args = ap.parse_args()
    clips = s1_clips("val")
    aligns = {s.sentence_id: s.align for s in sentences(None, split="val")}
    per = {name: widths(track) for name, track, _ in clips}
    keys = [k for k in next(iter(per.values())) if not k.startswith("_")]
    ship = [per[n]["corner (shipped)"] for n in per]
    print(f"1. widths on s1 val ({len(clips)} sentences, {sum(len(x) for x in ship)} frames)")
    print("| width | sd (IOD) | jitter | clip offsets | r with shipped, within clips |")
    for k in keys:
        xs = [per[n][k] for n in per]
        sd = float(np.concatenate(xs).std())
        r_ship = r(within(xs), within(ship))
        print(f"| {k} | {sd:.4f} | {jitter(xs):.1%} | {clip_offset_share(xs):.1%} | {r_ship:.3f} |")
    mo = [t.params[:, 2] for _, t, _ in clips]
    sd_mo = float(np.concatenate(mo).std())
    print(f"| (mouth_open, for scale) | {sd_mo:.4f} | {jitter(mo):.1%} | {clip_offset_share(mo):.1%} | |")

    a, b, c = (within([per[n][k] for n in per]) for k in ("corner (shipped)", "contour spread", "inner corners"))
    rab, rac, rbc = r(a, b), r(a, c), r(b, c)
    print(f"\n2. agreement within clips: corner-spread {rab:.3f}, corner-inner {rac:.3f}, spread-inner {rbc:.3f};")
    triad = rab * rac / rbc
    print(f"   triad reliability of the corner width r_ab r_ac / r_bc = {triad:.3f} (shared tracker noise inflates it)")
    rel = np.concatenate([per[n]["_scale_rel"] for n in per])
    drift = np.concatenate([per[n]["_corner_abs"] * (1 - 1 / per[n]["_scale_rel"]) for n in per])
    print(
        f"   pose-fit scale: sd {rel.std():.2%} around the clip median; its share of the within-clip width variance "
        f"{drift.var() / a.var():.1%}; r(scale, width) within clips {r(rel, a):.2f}"
    )

    cfg = video.ExtractConfig()
    rest_w: dict[str, list] = {"both silences (shipped)": [], "leading silence only": [], "trailing silence only": []}
    lead_trail = []
    for name, track, _ in clips:
        words = read_words(aligns[name])
        n = track.n_frames
        t = np.arange(n) / 30
        rest, _ = video.rest_frames(n, words, np.zeros(n), cfg)
        rest &= track.face_found
        spoken = [(s, e) for s, e, w in words if w.lower() not in SILENCE_WORDS]
        lead, trail = rest & (t < spoken[0][0]), rest & (t > spoken[-1][1])
        if lead.sum() < 3 or trail.sum() < 3:
            continue
        w = per[name]["_corner_abs"]
        gap = video.lip_gap(track.landmarks)
        lead_trail.append((np.median(w[lead]), np.median(w[trail]), np.median(gap[lead]) - np.median(gap[trail])))
        rest_w["both silences (shipped)"].append(per[name]["corner (shipped)"])
        rest_w["leading silence only"].append(w - np.median(w[lead]))
        rest_w["trailing silence only"].append(w - np.median(w[trail]))
    lt = np.array(lead_trail)
    d = lt[:, 0] - lt[:, 1]
    print(
        f"\n3. rest width, {len(lt)} clips with both silences: before the first word minus after the last "
        f"{d.mean():+.4f} IOD (sd {d.std():.4f}); r(before, after) across clips {r(lt[:, 0], lt[:, 1]):.2f}"
    )
    print(f"   inner-lip gap before minus after {lt[:, 2].mean():+.4f} IOD (sd {lt[:, 2].std():.4f})")
    for k, xs in rest_w.items():
        print(f"   rest = {k}: clip offsets {clip_offset_share(xs):.1%} of the variance")

    model = load_model(resolve_model(args.model))
    scores, items = evaluate_lips(model, clips)
    tru = [it[1][:, 1] for it in items]
    est = [it[2][:, 1] for it in items]
    T, E = np.concatenate(tru), np.concatenate(est)
    loud = np.concatenate([it[3] for it in items])
    speech = loud > np.quantile(loud, 0.4)
    err = [x - e for x, e in zip(tru, est, strict=True)]
    print(f"\n4. {args.model} model, val r(lip_stretch) {scores.r['lip_stretch']:.4f}:")
    r_means = r(np.array([x.mean() for x in tru]), np.array([x.mean() for x in est]))
    print(f"   within clips {r(within(tru), within(est)):.3f}; clip means {r_means:.2f}")
    slope = np.polyfit(E, T, 1)[0]
    right_means = np.concatenate([slope * (e - e.mean()) + x.mean() for x, e in zip(tru, est, strict=True)])
    print(f"   every clip mean replaced by the truth's (the within-clip estimate kept) {r(T, right_means):.3f}")
    smooth = np.concatenate([savgol_filter(x, 5, 2) for x in tru])
    print(f"   against the truth smoothed (5-frame Savitzky-Golay) {r(smooth, E):.3f}")
    r_speech, r_quiet = r(T[speech], E[speech]), r(T[~speech], E[~speech])
    print(f"   speech frames (loudest 60 %) {r_speech:.3f}, quiet frames {r_quiet:.3f}")
    share = float(np.var([x.mean() for x in err]) / np.var(T - E))
    print(f"   clip offsets' share of the error variance {share:.1%}")
    print(f"   power below 1 Hz / 1-3 Hz / above 3 Hz: truth {band_shares(tru)}, error {band_shares(err)}")


if __name__ == "__main__":
    main()
