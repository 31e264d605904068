"""Phone boundaries against the visual evidence: lip closure of /B P M/ in the real-lips tracks.

    python scripts/phone_lip_check.py PHONES.json [PHONES2.json ...]

For every /B P M/ (the last of a run) of the val and test GRID s1 sentences: the real lip height
(MediaPipe 0-17, the shared extraction's cached tracks) in the phone +-0.2 s; the closure is where
the height stays below 30 % of the way from its minimum to its maximum there, with sub-frame
threshold crossings. Prints, per labels file, the closure onset minus the phone start, the
release minus the phone end and the minimum's time minus the phone's midpoint (ms): median,
median absolute deviation (the spread a better labelling lowers; a constant offset is shared by
corpus and target and cancels) and the share off by more than 50 ms.
"""

from __future__ import annotations

import sys

import numpy as np

from assets import grid
from training.grid_phones import BILABIALS, read_grid_phones
from training.unitsel_eval import real_measures
from training.video import load_face_track


def offsets(phones, height: np.ndarray, fps: float = 30.0) -> list[tuple[float, float, float]]:
    """[(onset - start, release - end, minimum - midpoint)] in seconds per closing bilabial."""
    t = np.arange(len(height)) / fps
    out = []
    for i, p in enumerate(phones):
        if p.phoneme not in BILABIALS or (i + 1 < len(phones) and phones[i + 1].phoneme in BILABIALS):
            continue
        w = (t >= p.start_s - 0.2) & (t <= p.end_s + 0.2)
        if w.sum() < 5:
            continue
        hw, tw = height[w], t[w]
        k = int(np.argmin(hw))
        thr = hw[k] + 0.3 * (hw.max() - hw[k])
        a = k
        while a > 0 and hw[a - 1] < thr:
            a -= 1
        b = k
        while b < len(hw) - 1 and hw[b + 1] < thr:
            b += 1
        on = tw[a] if a == 0 else tw[a - 1] + (hw[a - 1] - thr) / (hw[a - 1] - hw[a]) / fps
        off = tw[b] if b == len(hw) - 1 else tw[b] + (thr - hw[b]) / (hw[b + 1] - hw[b]) / fps
        out.append((on - p.start_s, off - p.end_s, tw[k] - 0.5 * (p.start_s + p.end_s)))
    return out


def main(files: list[str]) -> None:
    labels = [read_grid_phones(f) for f in files]
    found: list[list[tuple[float, float, float]]] = [[] for _ in files]
    for s in grid.sentences():
        if s.split not in ("val", "test"):
            continue
        height = real_measures(load_face_track(s.video))[:, 0]
        for got, lab in zip(found, labels):
            got += offsets(lab[s.sentence_id].phones, height)
    for f, got in zip(files, found):
        arr = np.array(got) * 1000
        print(f"{f}: {len(arr)} bilabials")
        for j, name in enumerate(("closure onset - phone start", "release - phone end", "minimum - phone midpoint")):
            v = arr[:, j]
            med = np.median(v)
            print(
                f"  {name}: median {med:+.1f} ms, median |deviation| {np.median(np.abs(v - med)):.1f} ms, "
                f"|.| > 50 ms {100 * np.mean(np.abs(v) > 50):.0f} %"
            )


if __name__ == "__main__":
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    main(sys.argv[1:])
