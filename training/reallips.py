"""Real lips: GRID s1 face tracks as training utterances, acoustic variety, and the real-lips scores.

- :func:`grid_utterances` turns the cached :class:`~training.facetrack.FaceTrack` of every GRID s1
  sentence of a split (``assets.grid.split_of``) into corpus :class:`~training.corpus.Utterance`
  objects (source "video", speaker group ``grid:s1``), extracting what the cache lacks.
- :func:`speed_perturb` is the acoustic variety that serves other voices (Ko et al. 2015): the audio
  played ``factor`` times faster (resampled: formants, pitch and tempo all scale by ``factor``, like a
  shorter vocal tract and a faster talker), the lip track re-timed to match, so labels stay exact.
  Microphone variety (noise, reverberation, level, rate) comes from :mod:`training.augment`.
- :func:`voice_perturb` changes the voice without changing the timing: the formants scaled by one
  factor (a shorter or longer vocal tract, the variation that VTLP, Jaitly and Hinton 2013, models) and
  the pitch by another (Praat's "Change gender": PSOLA pitch change plus resampling, via parselmouth),
  so the lip track stays valid frame for frame. :func:`add_variety` applies a random draw to every
  speed copy, so a stranger's voice (tract length and pitch both unlike s1's) is covered at no extra
  training cost.
- Bilabial closures (/p b m/): for GRID s1 the phones of the shipped phone labels
  (:mod:`training.grid_phones`); for a GRID clip with only a word alignment, :func:`bilabial_spans`
  (which of the 51 GRID words hold a bilabial, and where); for real speech its aligned phones.
- :func:`score_lips` scores estimated against measured tracks per parameter: r at lag 0, the best lag
  within +-3 frames, nu = std(estimate) / std(truth) (seed 002, eq. 7), the share of bilabial closures
  the estimate reaches (mouth_open within ``closure_tol_iod`` of the closed pose, 0), and the loudness
  baseline (the frame's RMS level in dB as a mouth_open predictor).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from assets.grid import Split, read_words, sentences
from realtime_core import VISUAL_PARAMS
from realtime_core.features import loudness_db
from training.augment import AugmentConfig, augment
from training.corpus import Utterance
from training.errors import ConfigError, FileProblem
from training.params import FPS, n_frames_for

MOUTH_OPEN = VISUAL_PARAMS.index("mouth_open")

# Where the bilabial sits in each GRID word that has one ("initial": /b p/ opening the word,
# "final": /m/ ending it): bin, blue, by, place, please, and the letters b ("bee"), p ("pee"),
# m ("em"). No other GRID word (commands, colours, prepositions, letters, digits, adverbs) has one.
GRID_BILABIALS: dict[str, str] = {
    "bin": "initial",
    "blue": "initial",
    "by": "initial",
    "place": "initial",
    "please": "initial",
    "b": "initial",
    "p": "initial",
    "m": "final",
}
CLOSURE_S = 0.10
"""Length of the span searched for a closure at a bilabial word's start (or end for /m/): a stop
closure lasts 50-120 ms and the alignment's word boundary falls within a frame of it."""


def bilabial_spans(words: Sequence[tuple[float, float, str]]) -> list[tuple[float, float, str]]:
    """``[(start_s, end_s, word)]`` spans holding a /p b m/ closure, from a GRID word alignment."""
    out = []
    for a, b, w in words:
        where = GRID_BILABIALS.get(w.lower())
        if where == "initial":
            out.append((max(a - CLOSURE_S / 2, 0.0), min(a + CLOSURE_S, b), w))
        elif where == "final":
            out.append((max(b - CLOSURE_S, a), b + CLOSURE_S / 2, w))
    return out


# --------------------------------------------------------------------------- training data
def track_to_utterance(track, *, utt_id: str, speaker_group: str = "grid:s1") -> Utterance:
    """A :class:`FaceTrack` as a corpus utterance (source "video")."""
    return Utterance(
        id=utt_id,
        samples=track.samples,
        sample_rate_hz=track.sample_rate_hz,
        params=track.params,
        phonemes=(),
        voice=speaker_group,
        language="en",
        source="video",
        speaker_group=speaker_group,
    )


def grid_tracks(
    split: Split | None,
    *,
    root: str | Path | None = None,
    cache_dir: str | Path | None = None,
    progress: Callable | None = None,
    log: Callable[[str], None] | None = None,
) -> list:
    """``[(GridSentence, FaceTrack)]`` of a split (None = all), from the cache (extracting what is
    missing, one process). A sentence that cannot be measured is skipped with one line (``log``)."""
    from training.video import load_face_track

    wrap = progress or (lambda it, **_: it)
    out = []
    for s in wrap(sentences(root, split=split), desc=f"GRID s1 {split or 'all'}", unit="clip"):
        try:
            out.append((s, load_face_track(s.video, cache_dir=cache_dir, require_alignment=True)))
        except FileProblem as exc:
            (log or print)(f"skipped {s.video}: {exc.problem}")
    return out


def grid_utterances(split: Split | None, **kwargs) -> list[Utterance]:
    """The GRID s1 sentences of ``split`` as training utterances (see :func:`grid_tracks`)."""
    return [track_to_utterance(t, utt_id=f"grid-s1-{s.sentence_id}") for s, t in grid_tracks(split, **kwargs)]


def speed_audio(samples: np.ndarray, factor: float) -> np.ndarray:
    """``(n,)`` samples played ``factor`` times faster (0.8 .. 1.25) at the same rate: ``(~n / factor,)``
    float32, resampled, so pitch, formants and tempo scale together (the audio of :func:`speed_perturb`,
    for speech without a lip track). ``factor`` 1 returns ``samples``."""
    from scipy.signal import resample_poly

    if not 0.8 <= factor <= 1.25:
        raise ConfigError(f"speed factor must be in [0.8, 1.25], got {factor}")
    if factor == 1.0:
        return samples
    # play faster = keep the samples, declare them at rate * factor, convert back to the rate
    return resample_poly(np.asarray(samples, dtype=np.float64), 1000, round(1000 * factor)).astype(np.float32)


def speed_perturb(utt: Utterance, factor: float) -> Utterance:
    """``utt`` played ``factor`` times faster (0.8 .. 1.25): audio resampled (pitch, formants and
    tempo scale together, :func:`speed_audio`), the parameter track re-timed (frame k of the result is
    the original at ``k * factor / 30`` s, linear interpolation). ``factor`` 1 returns ``utt``."""
    audio = speed_audio(utt.samples, factor)  # checks the factor's range
    if factor == 1.0:
        return utt
    up, down = 1000, round(1000 * factor)
    n = n_frames_for(len(audio) / utt.sample_rate_hz)
    t_src = np.arange(len(utt.params)) / FPS
    t_new = np.minimum(np.arange(n) * down / up / FPS, t_src[-1])
    params = np.stack([np.interp(t_new, t_src, utt.params[:, j]) for j in range(utt.params.shape[1])], axis=1)
    return Utterance(
        id=f"{utt.id}-speed{factor:g}",
        samples=audio,
        sample_rate_hz=utt.sample_rate_hz,
        params=params,
        phonemes=(),
        voice=utt.voice,
        language=utt.language,
        source=utt.source,
        speaker_group=f"{utt.speaker_group}-speed{factor:g}",
    )


def voice_perturb(utt: Utterance, *, formant_ratio: float, pitch_ratio: float) -> Utterance:
    """``utt`` with its formants scaled by ``formant_ratio`` (0.7 .. 1.4; > 1 = a shorter vocal tract)
    and its median pitch by ``pitch_ratio`` (0.5 .. 2), tempo and length unchanged (so the parameter
    track is kept as it is). Praat's "Change gender" (pitch floor 75 Hz, ceiling 600 Hz) through
    parselmouth; an utterance with no voiced frame only has its formants shifted."""
    import parselmouth  # the `train` extra (pyproject.toml); imported only when voices are perturbed
    from parselmouth.praat import call

    if not 0.7 <= formant_ratio <= 1.4:
        raise ConfigError(f"formant ratio must be in [0.7, 1.4], got {formant_ratio}")
    if not 0.5 <= pitch_ratio <= 2.0:
        raise ConfigError(f"pitch ratio must be in [0.5, 2], got {pitch_ratio}")
    x = np.asarray(utt.samples, dtype=np.float64)
    snd = parselmouth.Sound(x, sampling_frequency=float(utt.sample_rate_hz))
    median_hz = call(call(snd, "To Pitch", 0.0, 75.0, 600.0), "Get quantile", 0.0, 0.0, 0.5, "Hertz")
    new_median = float(median_hz) * pitch_ratio if np.isfinite(median_hz) else 0.0  # 0 = keep the pitch
    y = call(snd, "Change gender", 75.0, 600.0, formant_ratio, new_median, 1.0, 1.0).values[0]
    # Praat may return a sample more or less; the timing (and so the lip track) is unchanged
    y = y[: len(x)] if len(y) >= len(x) else np.pad(y, (0, len(x) - len(y)))
    tag = f"-voice{formant_ratio:.3f}x{pitch_ratio:.3f}"
    return Utterance(
        id=f"{utt.id}{tag}",
        samples=y.astype(np.float32),
        sample_rate_hz=utt.sample_rate_hz,
        params=utt.params,
        phonemes=(),
        voice=utt.voice,
        language=utt.language,
        source=utt.source,
        speaker_group=f"{utt.speaker_group}{tag}",
    )


def microphone_copy(utt: Utterance, rng: np.random.Generator, config: AugmentConfig = AugmentConfig()) -> Utterance:
    """``utt`` through :func:`training.augment.augment` (noise, reverberation, level, rate)."""
    aug = augment(utt.samples, utt.sample_rate_hz, rng, config)
    n = n_frames_for(len(aug.samples) / aug.sample_rate_hz)
    params = (
        utt.params[:n]
        if len(utt.params) >= n
        else np.vstack([utt.params, np.repeat(utt.params[-1:], n - len(utt.params), 0)])
    )
    return Utterance(
        id=f"{utt.id}-mic",
        samples=aug.samples,
        sample_rate_hz=aug.sample_rate_hz,
        params=params,
        phonemes=(),
        voice=utt.voice,
        language=utt.language,
        source=utt.source,
        speaker_group=utt.speaker_group,
    )


@dataclass(frozen=True, kw_only=True)
class Variety:
    """How much acoustic variety is added to the real-lips training set.

    speeds:       speed-perturbation factors; each adds one copy of every utterance.
    formant_range, pitch_range: (low, high) ratios; when set, every speed copy also gets its voice
                  changed (:func:`voice_perturb`) with ratios drawn log-uniformly from these ranges
                  (each copy its own draw), so the data size is unchanged. None = plain speed copies.
    mic_copies:   copies of every (original and speed-perturbed) utterance through the microphone
                  chain (noise, reverberation, level, rate).
    seed:         seeds the microphone draws.
    """

    speeds: tuple[float, ...] = ()
    formant_range: tuple[float, float] | None = None
    pitch_range: tuple[float, float] | None = None
    mic_copies: int = 0
    seed: int = 0

    def __post_init__(self) -> None:
        for f in self.speeds:
            if not 0.8 <= f <= 1.25:
                raise ConfigError(f"speed factors must be in [0.8, 1.25], got {f}")
        if self.mic_copies < 0:
            raise ConfigError(f"mic_copies must be >= 0, got {self.mic_copies}")
        if (self.formant_range is None) != (self.pitch_range is None):
            raise ConfigError("formant_range and pitch_range go together (both None for plain speed copies)")
        for name, (lo_ok, hi_ok) in (("formant_range", (0.7, 1.4)), ("pitch_range", (0.5, 2.0))):
            rng = getattr(self, name)
            if rng is not None and not (len(rng) == 2 and lo_ok <= rng[0] <= rng[1] <= hi_ok):
                raise ConfigError(f"{name} must be (low, high) within [{lo_ok}, {hi_ok}], got {rng}")
        if self.formant_range is not None and not self.speeds:
            raise ConfigError("formant_range/pitch_range perturb the speed copies: give speeds too")


def add_variety(utts: Sequence[Utterance], variety: Variety) -> list[Utterance]:
    """The originals, one speed-perturbed copy per factor (voice-perturbed too when the variety has
    ranges), then ``mic_copies`` microphone copies of each."""
    out = list(utts)
    rng = np.random.default_rng(variety.seed)
    for f in variety.speeds:
        copies = [speed_perturb(u, f) for u in utts]
        if variety.formant_range is not None and variety.pitch_range is not None:
            (flo, fhi), (plo, phi) = variety.formant_range, variety.pitch_range
            copies = [
                voice_perturb(
                    u,
                    formant_ratio=float(np.exp(rng.uniform(np.log(flo), np.log(fhi)))),
                    pitch_ratio=float(np.exp(rng.uniform(np.log(plo), np.log(phi)))),
                )
                for u in copies
            ]
        out += copies
    base = list(out)
    for _ in range(variety.mic_copies):
        out += [microphone_copy(u, rng) for u in base]
    return out


# --------------------------------------------------------------------------- scores
def _lagged_r(truth: np.ndarray, est: np.ndarray, lag: int) -> float:
    a, b = (truth[: len(truth) - lag], est[lag:]) if lag >= 0 else (truth[-lag:], est[: len(est) + lag])
    if len(a) < 3 or a.std() == 0 or b.std() == 0:
        return 0.0
    return float(np.corrcoef(a, b)[0, 1])


@dataclass(frozen=True)
class LipScores:
    """Scores of a set of clips (frames pooled for r and nu; closures counted over all clips).

    r, best_lag, r_best, nu: per parameter name. closure_rate: estimated mouth_open reaches the
    closed pose (<= ``tol``) in this share of bilabial spans (``n_closures``); truth_closure_rate
    is the same for the measured track (how well the spans find closures). r_loudness: the
    loudness baseline's r with the true mouth_open. per_clip: name -> {r mouth_open, r loudness}.
    """

    r: dict
    best_lag: dict
    r_best: dict
    nu: dict
    closure_rate: float
    truth_closure_rate: float
    n_closures: int
    r_loudness: float
    n_frames: int
    per_clip: dict = field(default_factory=dict)

    def as_json(self) -> dict:
        def rnd(d: dict) -> dict:
            return {k: round(float(v), 4) for k, v in d.items()}

        return {
            "r": rnd(self.r),
            "best_lag": self.best_lag,
            "r_best": rnd(self.r_best),
            "nu": rnd(self.nu),
            "closure_rate": round(self.closure_rate, 4),
            "truth_closure_rate": round(self.truth_closure_rate, 4),
            "n_closures": self.n_closures,
            "r_loudness": round(self.r_loudness, 4),
            "n_frames": self.n_frames,
            "per_clip": {k: rnd(v) for k, v in self.per_clip.items()},
        }


CLOSURE_TOL_IOD = 0.01
"""mouth_open at or below this (IOD; 0 = the rest face) is the closed pose: a closure the estimate reaches
(:func:`score_lips`) and, in a corpus without phone labels, a closure the measured lips make
(:func:`lip_closure_spans`)."""


def lip_closure_spans(
    params: np.ndarray, level_db: np.ndarray, *, below_peak_db: float | None = None
) -> list[tuple[float, float, str]]:
    """``[(start_s, end_s, "lips")]``: the measured lips' own closures, the stand-in for /p b m/ labels where a
    corpus has none. params ``(T, 4)`` IOD, level_db ``(T,)`` (``loudness_db``). A closure is a run of frames at
    the closed pose (mouth_open <= :data:`CLOSURE_TOL_IOD`, the closure metric's own test) inside speech, the
    frames from the clip's first to its last within ``below_peak_db`` of its loudest (default: the extraction's
    quiet rule, ``ExtractConfig.quiet_below_db``), so the closed lips before and after the sentence are not
    counted. A run shorter than ``CLOSURE_S`` is widened to it about its centre, as a stop closure lasts 50-120
    ms and a phone label spans it: the estimate may reach the pose anywhere in that span, as with labels."""
    if below_peak_db is None:
        from training.video import ExtractConfig

        below_peak_db = ExtractConfig().quiet_below_db
    T = min(len(params), len(level_db))
    loud = np.flatnonzero(level_db[:T] >= level_db[:T].max() - below_peak_db) if T else np.array([], int)
    if not len(loud):
        return []
    closed = np.zeros(T + 2, bool)
    lo, hi = loud[0], loud[-1] + 1
    closed[lo + 1 : hi + 1] = params[lo:hi, MOUTH_OPEN] <= CLOSURE_TOL_IOD
    edges = np.flatnonzero(np.diff(closed.astype(np.int8)))
    out = []
    for a, b in zip(edges[::2], edges[1::2], strict=True):  # closed frames a .. b - 1
        start, end = a / FPS, (b - 1) / FPS
        pad = max(CLOSURE_S - (end - start), 0.0) / 2
        out.append((max(start - pad, 0.0), end + pad, "lips"))
    return out


def score_lips(
    items: Sequence[tuple[str, np.ndarray, np.ndarray, np.ndarray, list]], *, closure_tol_iod: float = CLOSURE_TOL_IOD
) -> LipScores:
    """``items``: (name, truth (T, 4), estimate (T', 4), loudness (T,) dB, bilabial spans [(a, b, w)]).

    Tracks are cut to the shorter length; frames of all clips are pooled for r / lags / nu."""
    truths, ests, louds, per_clip = [], [], [], {}
    hits = true_hits = n = 0
    for name, truth, est, loud, spans in items:
        T = min(len(truth), len(est), len(loud))
        truth, est, loud = truth[:T], est[:T], loud[:T]
        truths.append(truth)
        ests.append(est)
        louds.append(loud)
        per_clip[name] = {
            "r_mouth_open": _lagged_r(truth[:, MOUTH_OPEN], est[:, MOUTH_OPEN], 0),
            "r_loudness": _lagged_r(truth[:, MOUTH_OPEN], loud, 0),
        }
        t = np.arange(T) / FPS
        for a, b, _ in spans:
            sel = (t >= a - 0.5 / FPS) & (t <= b + 0.5 / FPS)
            if not sel.any():
                continue
            n += 1
            hits += bool(est[sel, MOUTH_OPEN].min() <= closure_tol_iod)
            true_hits += bool(truth[sel, MOUTH_OPEN].min() <= closure_tol_iod)
    tr, es, lo = np.concatenate(truths), np.concatenate(ests), np.concatenate(louds)
    r, lag, rb, nu = {}, {}, {}, {}
    for j, name in enumerate(VISUAL_PARAMS):
        r[name] = _lagged_r(tr[:, j], es[:, j], 0)
        # lags are found per clip boundary-free: pool shifted clips
        by_lag = {}
        for L in range(-3, 4):
            a = np.concatenate([x[: len(x) - L, j] if L >= 0 else x[-L:, j] for x in truths])
            b = np.concatenate([y[L:, j] if L >= 0 else y[: len(y) + L, j] for y in ests])
            by_lag[L] = float(np.corrcoef(a, b)[0, 1]) if a.std() > 0 and b.std() > 0 else 0.0
        lag[name] = max(by_lag, key=by_lag.__getitem__)
        rb[name] = by_lag[lag[name]]
        nu[name] = float(es[:, j].std() / tr[:, j].std()) if tr[:, j].std() > 0 else float("nan")
    return LipScores(
        r=r,
        best_lag=lag,
        r_best=rb,
        nu=nu,
        closure_rate=hits / n if n else float("nan"),
        truth_closure_rate=true_hits / n if n else float("nan"),
        n_closures=n,
        r_loudness=_lagged_r(tr[:, MOUTH_OPEN], lo, 0),
        n_frames=len(tr),
        per_clip=per_clip,
    )


def lip_items(
    model,
    clips: Sequence[tuple[str, np.ndarray, int, np.ndarray, list]],
    *,
    lag: int = 0,
    progress: Callable | None = None,
    desc: str = "scoring",
) -> list:
    """Run the live path of ``model`` (with ``lag`` frames of fixed-lag smoothing) on ``clips`` (name,
    samples, rate_hz, truth (T, 4), bilabial spans [(start_s, end_s, label)]) -> items for :func:`score_lips`.
    ``progress(iterable, desc=, unit=)`` (e.g. assets.progress.Progress) wraps the clips (about a second each)."""
    from realtime_core.inversion import StreamConfig
    from realtime_core.pipeline import speech_to_params

    wrap = progress or (lambda it, **_: it)
    out = []
    for name, samples, rate, truth, spans in wrap(clips, desc=desc, unit="clip"):
        est = speech_to_params(model, samples, rate, stream=StreamConfig(lag=lag))
        out.append((name, truth, est, loudness_db(samples, rate, len(truth)), list(spans)))
    return out


def words_of(video: Path) -> list | None:
    """The word alignment beside a video (assets.grid.align_for_video), or None."""
    from assets.grid import align_for_video

    align = align_for_video(video)
    return read_words(align) if align else None


# --------------------------------------------------------------------------- evaluation sets
S1_CLIPS_IN_GRID = frozenset({"bbaf2n"})
"""Clips of ``video/grid`` spoken by s1 (the data README: "four talkers, one of them s1 (bbaf2n)"):
never counted as another talker."""


def other_talker_clips(
    folder: str | Path,
    *,
    cache_dir: str | Path | None = None,
    progress: Callable | None = None,
    desc: str = "other talkers",
) -> list:
    """``[(name, FaceTrack, bilabial spans)]`` of the talking-face clips in ``folder`` not spoken by s1
    (spans from a GRID word alignment beside the clip, :func:`bilabial_spans`; none without one).
    ``progress(iterable, desc=, unit=)`` (e.g. assets.progress.Progress) wraps the clips: measuring one takes
    seconds."""
    from training.video import VIDEO_SUFFIXES, load_face_track

    wrap = progress or (lambda it, **_: it)
    clips = sorted(p for p in Path(folder).iterdir() if p.suffix.lower() in VIDEO_SUFFIXES)
    clips = [p for p in clips if not any(p.stem.endswith(s) for s in S1_CLIPS_IN_GRID)]
    out = []
    for clip in wrap(clips, desc=desc, unit="clip"):
        out.append((clip.stem, load_face_track(clip, cache_dir=cache_dir), bilabial_spans(words_of(clip) or [])))
    return out


def s1_clips(
    split: Split,
    *,
    root: str | Path | None = None,
    cache_dir: str | Path | None = None,
    progress: Callable | None = None,
    phones: dict | None = None,
) -> list:
    """``[(sentence_id, FaceTrack, bilabial spans)]`` of a GRID s1 split. The spans are the /p b m/
    phones of the shipped GRID s1 phone labels (``training.grid_phones``; ``phones`` = {id:
    Alignment} to use others), else from the word alignment (:func:`bilabial_spans`)."""
    if phones is None:
        from training.grid_phones import read_grid_phones

        phones = read_grid_phones()
    out = []
    for s, t in grid_tracks(split, root=root, cache_dir=cache_dir, progress=progress):
        al = phones.get(s.sentence_id)
        spans = phone_bilabial_spans(al.phones) if al is not None else bilabial_spans(read_words(s.align))
        out.append((s.sentence_id, t, spans))
    return out


def phone_bilabial_spans(phones: Sequence) -> list[tuple[float, float, str]]:
    """``[(start_s, end_s, phone)]`` of the /p b m/ phones of a phone timeline (``PhonemeSegment``)."""
    return [(p.start_s, p.end_s, p.phoneme) for p in phones if p.phoneme.rstrip("012") in BILABIAL_PHONES]


def evaluate_lips(
    model, clips: Sequence[tuple[str, Any, list]], *, lag: int = 0, progress: Callable | None = None
) -> tuple[LipScores, list]:
    """Score ``model``'s live path (``lag`` frames of smoothing) on ``[(name, FaceTrack, bilabial spans)]``;
    returns the scores and the items. ``progress``: as :func:`lip_items`'."""
    audio = [(n, t.samples, t.sample_rate_hz, t.params, w) for n, t, w in clips]
    items = lip_items(model, audio, lag=lag, progress=progress)
    return score_lips(items), items


def lips_markdown(title: str, s: LipScores, *, note: str = "", goals: dict | None = None) -> str:
    """A markdown section: the per-parameter table and the mouth_open summary."""
    lines = [f"## {title}", ""]
    if note:
        lines += [note, ""]
    lines += [
        f"{len(s.per_clip)} clips, {s.n_frames} frames pooled; loudness baseline r(mouth_open) = "
        f"{s.r_loudness:.3f}; bilabial closures reached: "
        + (
            f"{s.closure_rate:.0%} of {s.n_closures} (the truth track itself: {s.truth_closure_rate:.0%})"
            if s.n_closures
            else "no word alignment, not measured"
        ),
        "",
        "| parameter | r (lag 0) | best lag (frames) | r at best lag | nu = std(est)/std(true) |",
        "|---|---:|---:|---:|---:|",
    ]
    for p in VISUAL_PARAMS:
        lines.append(f"| {p} | {s.r[p]:.3f} | {s.best_lag[p]:+d} | {s.r_best[p]:.3f} | {s.nu[p]:.2f} |")
    if len(s.per_clip) <= 10:
        lines += ["", "| clip | r mouth_open | r loudness |", "|---|---:|---:|"]
        lines += [f"| {k} | {v['r_mouth_open']:.3f} | {v['r_loudness']:.3f} |" for k, v in s.per_clip.items()]
    if goals:
        lines += ["", "Goals: " + "; ".join(f"{k} {'met' if ok else 'MISSED'}" for k, ok in goals.items())]
    return "\n".join(lines) + "\n\n"


def plot_lips(items: Sequence, scores: LipScores, png: Path, *, title: str, n_clips: int = 3) -> Path:
    """PNG: measured vs estimated mouth_open (and lip_stretch) for the first clips, bilabial spans
    shaded, and r per parameter beside the loudness baseline."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    show = list(items)[:n_clips]
    fig, axes = plt.subplots(len(show) + 1, 1, figsize=(10, 2.3 * (len(show) + 1)))
    for ax, (name, truth, est, _loud, spans) in zip(axes, show):
        T = min(len(truth), len(est))
        t = np.arange(T) / FPS
        ax.plot(t, truth[:T, MOUTH_OPEN], "k-", lw=2, label="mouth_open measured")
        ax.plot(t, est[:T, MOUTH_OPEN], color="tab:red", lw=1.5, label="mouth_open estimated")
        j = VISUAL_PARAMS.index("lip_stretch")
        ax.plot(t, truth[:T, j], color="tab:green", lw=1, alpha=0.6, label="lip_stretch measured")
        ax.plot(t, est[:T, j], color="tab:green", lw=1, ls="--", label="lip_stretch estimated")
        for a, b, _ in spans:
            ax.axvspan(a, b, color="tab:blue", alpha=0.15)
        ax.axhline(0, color="grey", lw=0.5)
        ax.set_title(f"{name} (blue: bilabial closures)", fontsize=9)
        ax.set_ylabel("IOD")
    axes[0].legend(fontsize=7, loc="upper right")
    ax = axes[-1]
    x = np.arange(len(VISUAL_PARAMS))
    ax.bar(x, [scores.r[p] for p in VISUAL_PARAMS], color="tab:red", label="model r (lag 0)")
    ax.axhline(scores.r_loudness, color="tab:orange", ls="--", label=f"loudness r(mouth_open) {scores.r_loudness:.2f}")
    ax.set_xticks(x, VISUAL_PARAMS)
    ax.set_ylim(min(0, *scores.r.values()) - 0.05, 1)
    ax.legend(fontsize=7)
    ax.set_title(title, fontsize=9)
    fig.tight_layout()
    png.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(png, dpi=80)
    plt.close(fig)
    return png


BILABIAL_PHONES = frozenset({"p", "b", "m", "P", "B", "M", "m̩"})
"""/p b m/ in the phone inventories of the alignments (ARPAbet upper case, espeak and IPA lower case)."""


def real_speech_clips(root: str | Path) -> list:
    """Real recordings with phone alignments under ``root`` (ARCTIC, LibriVox, praatio):
    ``[(name, samples, rate_hz, rules truth (T, 4), bilabial spans)]``. The truth is the articulatory
    rules on the real phone timings (the ceiling of any audio model against them is their own
    ~0.5-0.6 against real lips); the spans are the aligned /p b m/ phones, where the rules close
    the lips exactly: a closure check on other voices that needs no video."""
    from assets.audio import read_audio
    from training.alignments import find_aligned_audio
    from training.articulatory import render_params

    out = []
    for wav, align in find_aligned_audio(root):
        samples, rate = read_audio(wav)
        n = n_frames_for(len(samples) / rate)
        truth = render_params(align.phones, n, inventory=align.inventory)
        out.append((wav.stem, samples, rate, truth, phone_bilabial_spans(align.phones)))
    return out


def score_real_speech(model, clips: Sequence) -> LipScores:
    """:func:`score_lips` of ``model``'s live path on :func:`real_speech_clips`."""
    from realtime_core.pipeline import speech_to_params

    items = [
        (n, truth, speech_to_params(model, x, rate), loudness_db(x, rate, len(truth)), spans)
        for n, x, rate, truth, spans in clips
    ]
    return score_lips(items)
