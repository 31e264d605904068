"""Fitting the learned readout of a model (:mod:`realtime_core.readout`) on real lips, re-runnable on any HMM.

- :func:`trace_clips` runs a model's live path (front end, lag-0 inverter, no readout, no output stage)
  over clips and keeps, per frame, what the readout sees: the raw eq. 7 estimate, the component
  posteriors and the centred audio row.
- :func:`fit_readout` fits one readout on traced train clips: scikit-learn's ``Ridge`` for a linear map
  (hidden = 0), its ``MLPRegressor`` (one ReLU layer, inputs standardised, early stopping on a 10 % slice
  of the train frames, seeded) otherwise; the input scaling is folded into the stored weights, and so is a
  per-parameter loss weight (the targets scaled by sqrt(w) for the fit, the output layer scaled back).
- :func:`choose_readout` fits every candidate on the train split, scores each on the val split through
  the model's output stage, keeps the best by the mean r of the four parameters, then re-chooses the
  closure band on val (the highest r(mouth_open) keeping >= ``min_closure`` of the bilabial closures;
  the readout changes how deep the dips go). The test split is never looked at.
- A studio's own corpus (``facecast readout --corpus DIR``) stands in for GRID s1's train/val: :func:`split_corpus`
  splits its utterances by sentence into a fitting and a choosing part, :func:`corpus_clips` gives each its
  closure events (its /p b m/ phone labels, else the measured lips' own closures, a proxy).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from realtime_core import VISUAL_PARAMS
from realtime_core.avmodel import AvModel
from realtime_core.features import loudness_db
from realtime_core.output import OutputStage
from realtime_core.readout import POSTERIOR_KINDS, Readout, posterior_features, readout_features
from training.errors import ConfigError
from training.reallips import LipScores, score_lips


@dataclass(frozen=True)
class Traced:
    """One clip through a model: name, truth ``(T, Dv)``, raw ``(T, Dv)``, component posteriors
    ``(T, N*M)``, centred audio ``(T, Da)``, loudness ``(T,)`` dB, bilabial spans."""

    name: str
    truth: np.ndarray
    raw: np.ndarray
    post: np.ndarray
    audio: np.ndarray
    loudness: np.ndarray
    spans: list


@dataclass(frozen=True, kw_only=True)
class ReadoutSpec:
    """One candidate: taps (K >= 1), audio (use the centred audio row), posteriors ("none", "state",
    "component"), hidden (0 = linear ridge, else ReLU units), alpha (the L2 penalty: ridge alpha, or
    the MLP's), seed (MLP initialisation and early-stopping split), max_iter (MLP epochs), ensemble (MLPs
    with seeds seed, seed + 1, ... averaged: stored as one layer of ensemble x hidden units whose output
    weights are divided by ensemble), loss_weight (each parameter's weight in the fit's squared error: four
    positive floats in ``VISUAL_PARAMS`` order, or a mapping by parameter name, the others 1; stored as the
    four-tuple). The loss weight changes only the fit: the stored readout's form is the same."""

    taps: int = 5
    audio: bool = True
    posteriors: str = "state"
    hidden: int = 64
    alpha: float = 1e-3
    seed: int = 0
    max_iter: int = 200
    ensemble: int = 1
    loss_weight: tuple[float, ...] | Mapping[str, float] = (1.0, 1.0, 1.0, 1.0)

    def __post_init__(self) -> None:
        bad = self.taps < 1 or self.hidden < 0 or self.alpha < 0 or self.ensemble < 1
        if bad or self.posteriors not in POSTERIOR_KINDS or (self.hidden == 0 and self.ensemble != 1):
            raise ConfigError(f"invalid readout candidate {self}")
        object.__setattr__(self, "loss_weight", _loss_weight(self.loss_weight))

    @property
    def weights(self) -> np.ndarray:
        """The loss weight per parameter, ``(4,)`` in ``VISUAL_PARAMS`` order."""
        return np.asarray(self.loss_weight, dtype=np.float64)

    def as_json(self) -> dict[str, Any]:
        return {
            "taps": self.taps,
            "audio": self.audio,
            "posteriors": self.posteriors,
            "hidden": self.hidden,
            "alpha": self.alpha,
            "seed": self.seed,
            "max_iter": self.max_iter,
            "ensemble": self.ensemble,
            "loss_weight": dict(zip(VISUAL_PARAMS, self.weights.tolist(), strict=True)),
        }


def _loss_weight(value: Any) -> tuple[float, ...]:
    """``ReadoutSpec.loss_weight`` as four floats in ``VISUAL_PARAMS`` order, or ConfigError naming the problem."""
    if isinstance(value, Mapping):
        unknown = sorted(str(k) for k in value if k not in VISUAL_PARAMS)
        if unknown:
            known = ", ".join(VISUAL_PARAMS)
            raise ConfigError(f"readout loss weight for unknown parameter(s) {unknown}: known are {known}")
        named = dict(value)
        value = tuple(named.get(p, 1.0) for p in VISUAL_PARAMS)
    try:
        weights = tuple(float(w) for w in value)
    except (TypeError, ValueError):
        raise ConfigError(f"readout loss weight must be four numbers or a mapping by name, got {value!r}") from None
    if len(weights) != len(VISUAL_PARAMS):
        names = ", ".join(VISUAL_PARAMS)
        raise ConfigError(f"readout loss weight needs {len(VISUAL_PARAMS)} values ({names}), got {len(weights)}")
    bad = [f"{p}={w}" for p, w in zip(VISUAL_PARAMS, weights, strict=True) if not (math.isfinite(w) and w > 0)]
    if bad:
        raise ConfigError(f"readout loss weights must be finite and > 0: {', '.join(bad)}")
    return weights


def trace_clips(
    model: AvModel,
    clips: Sequence[tuple[str, Any, list]],
    *,
    warps: Sequence[float] | None = None,
    progress: Callable | None = None,
) -> list:
    """``[(name, FaceTrack, bilabial spans)]`` -> ``[Traced]`` through ``model``'s live path at lag 0.
    warps: one filterbank warp per clip (:meth:`AvModel.front_end`; a vocal-tract-length copy of the
    clip's voice, its lips unchanged), None = the voice as recorded."""
    from realtime_core.features.resample import resample_audio

    if warps is not None and len(warps) != len(clips):
        raise ConfigError(f"{len(warps)} warps for {len(clips)} clips")
    wrap = progress or (lambda it, **_: it)
    inv = model.inverter()
    out = []
    for i, (name, track, spans) in enumerate(wrap(clips, desc="readout inputs", unit="clip")):
        x = np.asarray(track.samples, dtype=np.float64)
        if track.sample_rate_hz != model.sample_rate_hz:
            x = resample_audio(x, track.sample_rate_hz, model.sample_rate_hz)
        warp = 1.0 if warps is None else float(warps[i])
        fe = model.front_end(warp=warp)
        oa = np.concatenate([fe.push(x), fe.flush()])
        raw, post, audio = inv.trace(oa)
        T = min(len(raw), len(track.params))
        loud = loudness_db(track.samples, track.sample_rate_hz, len(track.params))
        tag = "" if warps is None else f"-warp{warp:.3f}"
        out.append(Traced(f"{name}{tag}", track.params[:T], raw[:T], post[:T], audio[:T], loud[:T], list(spans)))
    return out


@dataclass(frozen=True, kw_only=True)
class VtlpConfig:
    """Vocal-tract-length copies of the readout's train clips (issue 10: one training talker; the readout
    learns to read other vocal tracts the same way). copies: copies of every clip (0 = none); warp_range:
    (low, high) filterbank warps (``MfccConfig.warp``), each copy of each clip its own uniform draw; seed."""

    copies: int = 0
    warp_range: tuple[float, float] = (0.88, 1.12)
    seed: int = 0

    def __post_init__(self) -> None:
        lo, hi = self.warp_range
        if self.copies < 0 or not 0.8 <= lo <= hi <= 1.25:
            raise ConfigError(f"invalid VTLP copies {self}: copies >= 0, 0.8 <= low <= high <= 1.25")

    def as_json(self) -> dict[str, Any]:
        return {"copies": self.copies, "warp_range": list(self.warp_range), "seed": self.seed}


def vtlp_copies(
    model: AvModel, clips: Sequence[tuple[str, Any, list]], config: VtlpConfig, *, progress: Callable | None = None
) -> list:
    """``config.copies`` warped traces of every clip (:func:`trace_clips` with a warp drawn per clip)."""
    rng = np.random.default_rng(config.seed)
    out: list = []
    for _ in range(config.copies):
        warps = [float(w) for w in rng.uniform(*config.warp_range, len(clips))]
        out += trace_clips(model, clips, warps=warps, progress=progress)
    return out


CHOOSE_FRACTION = 0.2
"""Share of a corpus's utterances that choose the readout and the closure band (the rest fit it): GRID s1's
val split is about this share of its train + val."""
MIN_PART_UTTERANCES = 4
"""Fewest utterances in each part: fewer make the choice (of a readout, of a band) a coin toss."""


def split_corpus(utts: Sequence[Any], *, choose_fraction: float = CHOOSE_FRACTION, where: str = "corpus") -> tuple:
    """``(fit, choose)``: a corpus's utterances (one sentence each) split by sentence, deterministically: in
    order of id, utterance i chooses when ``floor((i + 1) f) > floor(i f)`` (f = ``choose_fraction``), so
    ``floor(n f)`` utterances spread evenly over the corpus choose and the same corpus always splits the same
    way. ConfigError naming ``where`` when a part would hold fewer than :data:`MIN_PART_UTTERANCES`."""
    if not 0.0 < choose_fraction < 1.0:
        raise ConfigError(f"the choose fraction must be in (0, 1), got {choose_fraction}")
    ordered = sorted(utts, key=lambda u: u.id)
    pick = [math.floor((i + 1) * choose_fraction) > math.floor(i * choose_fraction) for i in range(len(ordered))]
    fit = [u for u, c in zip(ordered, pick, strict=True) if not c]
    choose = [u for u, c in zip(ordered, pick, strict=True) if c]
    if min(len(fit), len(choose)) < MIN_PART_UTTERANCES:
        raise ConfigError(
            f"{where}: {len(ordered)} utterances are too few for a readout: {len(fit)} to fit and {len(choose)} to "
            f"choose (choose fraction {choose_fraction}), each part needs at least {MIN_PART_UTTERANCES}"
        )
    return fit, choose


def corpus_clips(utts: Sequence[Any]) -> tuple[list, dict[str, int]]:
    """``[(id, utterance, closure spans)]`` of corpus utterances for :func:`trace_clips` (an ``Utterance`` has a
    face track's samples, rate and params), and how many utterances had each kind of closure event: "phones"
    (the /p b m/ phones of the utterance's phone labels) or "lips" (none: the measured lips' own closures,
    :func:`training.reallips.lip_closure_spans`, a proxy)."""
    from training.reallips import lip_closure_spans, phone_bilabial_spans

    out, kinds = [], {"phones": 0, "lips": 0}
    for u in utts:
        if u.phonemes:
            spans = phone_bilabial_spans(u.phonemes)
            kinds["phones"] += 1
        else:
            spans = lip_closure_spans(u.params, loudness_db(u.samples, u.sample_rate_hz, len(u.params)))
            kinds["lips"] += 1
        out.append((u.id, u, spans))
    return out, kinds


def _features(spec: ReadoutSpec, model: AvModel, clips: Sequence[Traced]) -> np.ndarray:
    h = model.hmm
    return np.concatenate(
        [
            readout_features(
                c.raw,
                c.audio if spec.audio else c.audio[:, :0],
                posterior_features(spec.posteriors, c.post, h.n_states, h.n_mix),
                taps=spec.taps,
            )
            for c in clips
        ]
    )


def _readout(spec: ReadoutSpec, model: AvModel, w1, b1, w2, b2, metadata: dict) -> Readout:
    h = model.hmm
    return Readout(
        taps=spec.taps,
        audio=spec.audio,
        posteriors=spec.posteriors,
        n_states=h.n_states,
        n_mix=h.n_mix,
        n_audio=h.n_audio,
        n_visual=h.n_visual,
        w1=w1,
        b1=b1,
        w2=w2,
        b2=b2,
        metadata=metadata,
    )


def fit_readout(model: AvModel, train: Sequence[Traced], spec: ReadoutSpec) -> Readout:
    """Fit one readout of ``spec`` for ``model`` on traced train clips (targets: their truth).

    ``spec.loss_weight``: the fits minimise an unweighted squared error summed over the outputs, so a
    parameter of weight w is fitted as its target times sqrt(w) (its error then counts w times) and the
    output layer (w2, b2) divided by sqrt(w) afterwards: the same readout form, the live path unchanged.
    Weights of 1 scale by exactly 1.0, so the fit is bit for bit the unweighted one. (Ridge fits each
    output on its own, so a weight changes a linear readout only by rounding.)"""
    from sklearn.linear_model import Ridge

    phi = _features(spec, model, train)
    scale = np.sqrt(spec.weights)  # (4,)
    y = np.concatenate([c.truth for c in train]) * scale
    meta = {**spec.as_json(), "train_frames": len(y)}
    if spec.hidden == 0:
        lin = Ridge(alpha=spec.alpha).fit(phi, y)
        w2, b2 = lin.coef_.T / scale, lin.intercept_ / scale
        return _readout(spec, model, np.zeros((phi.shape[1], 0)), np.zeros(0), w2, b2, meta)
    w1, b1, w2, b2, epochs = mlp_layers(spec, phi, y)
    meta["epochs"] = epochs if spec.ensemble > 1 else epochs[0]
    return _readout(spec, model, w1, b1, w2 / scale, b2 / scale, meta)


def mlp_regressor(spec: ReadoutSpec, k: int) -> Any:
    """The ``k``-th net of ``spec``'s ensemble (scikit-learn ``MLPRegressor``, unfitted, seed ``spec.seed + k``)."""
    from sklearn.neural_network import MLPRegressor

    return MLPRegressor(
        hidden_layer_sizes=(spec.hidden,),
        activation="relu",
        alpha=spec.alpha,
        early_stopping=True,
        max_iter=spec.max_iter,
        random_state=spec.seed + k,
    )


def mlp_layers(spec: ReadoutSpec, phi: np.ndarray, y: np.ndarray) -> tuple[Any, Any, Any, Any, list[int]]:
    """Fit ``spec``'s ensemble of ReLU nets on standardised inputs ``phi`` (frames, d) against ``y``
    (frames, 4) and fold them into one layer: (w1 (d, E*h), b1 (E*h,), w2 (E*h, 4), b2 (4,), epochs per net),
    the scaler folded into w1/b1 and the ensemble mean into w2/b2 (the live readout's form)."""
    from sklearn.preprocessing import StandardScaler

    from training.mapper import fit_within_budget

    scaler = StandardScaler().fit(phi)
    sd = scaler.scale_
    w1s, b1s, w2s, b2s, epochs = [], [], [], [], []
    for k in range(spec.ensemble):
        mlp = fit_within_budget(mlp_regressor(spec, k), scaler.transform(phi), y)
        epochs.append(int(mlp.n_iter_))
        # relu(((phi - mu) / sd) @ W + b) = relu(phi @ (W / sd) + (b - (mu / sd) @ W))
        w1s.append(mlp.coefs_[0] / sd[:, None])
        b1s.append(mlp.intercepts_[0] - (scaler.mean_ / sd) @ mlp.coefs_[0])
        w2s.append(mlp.coefs_[1] / spec.ensemble)
        b2s.append(mlp.intercepts_[1] / spec.ensemble)
    return np.concatenate(w1s, axis=1), np.concatenate(b1s), np.concatenate(w2s), np.sum(b2s, axis=0), epochs


def estimates(model: AvModel, clips: Sequence[Traced], readout: Readout | None, band: float) -> list:
    """``score_lips`` items of ``clips`` with ``readout`` (None: eq. 7 as is) and an output stage of ``band``
    (what the live path of ``replace(model, readout=readout, closure_band=band)`` emits; tested equal)."""
    stage = OutputStage(model.visual_floor, band)
    out = []
    for c in clips:
        raw = c.raw if readout is None else readout.apply(c.raw, c.post, c.audio)
        out.append((c.name, c.truth, stage(raw.copy()), c.loudness, c.spans))
    return out


def choose_readout(
    model: AvModel,
    train: Sequence[Traced],
    val: Sequence[Traced],
    specs: Sequence[ReadoutSpec],
    *,
    bands: Sequence[float] = (0.02, 0.025, 0.03, 0.035, 0.04, 0.045, 0.05),
    min_closure: float = 0.90,
    log: Callable[[str], None] = print,
) -> tuple[AvModel, dict[str, Any]]:
    """The model with the best readout of ``specs`` (fitted on ``train``, chosen on ``val``) and its closure
    band re-chosen on ``val``; and a JSON-able report of every candidate's val scores."""
    if not specs:
        raise ConfigError("no readout candidates given")
    base = score_lips(estimates(model, val, None, model.closure_band))
    rows: list[dict[str, Any]] = [{"readout": None, "band": model.closure_band, **_summary(base)}]
    log(f"val without readout (band {model.closure_band}): {_line(base)}")
    best: tuple[float, Readout, LipScores] | None = None
    for spec in specs:
        ro = fit_readout(model, train, spec)
        s = score_lips(estimates(model, val, ro, model.closure_band))
        rows.append({"readout": spec.as_json(), "band": model.closure_band, **_summary(s)})
        log(f"val {spec.as_json()}: {_line(s)}")
        key = float(np.mean([s.r[p] for p in VISUAL_PARAMS]))
        if best is None or key > best[0]:
            best = (key, ro, s)
    assert best is not None
    _, ro, _ = best
    band_rows = []

    def scored(band: float) -> LipScores:
        s = score_lips(estimates(model, val, ro, band))
        band_rows.append({"band": band, **_summary(s)})
        log(f"val band {band}: {_line(s)}")
        return s

    band, s = choose_band(scored, bands=bands, min_closure=min_closure)
    ro = replace(ro, metadata={**ro.metadata, "val": _summary(s), "band": band})
    report = {"candidates": rows, "bands": band_rows, "chosen": {**ro.metadata}, "val_without": _summary(base)}
    log(f"chosen {ro.metadata}")
    return replace(model, readout=ro, closure_band=band), report


def choose_band(
    score: Callable[[float], LipScores], *, bands: Sequence[float], min_closure: float
) -> tuple[float, LipScores]:
    """The closure band (IOD) of ``bands`` with the highest ``score(band)`` r(mouth_open) among those reaching
    ``min_closure`` of the closures, and its scores; when none does, the widest band (it closes the most)."""
    scores = {band: score(band) for band in bands}
    kept = [band for band in bands if scores[band].closure_rate >= min_closure]
    # max() keeps the first of equal r, as the bands are listed.
    band = max(kept, key=lambda b: scores[b].r["mouth_open"]) if kept else max(bands)
    return band, scores[band]


def _summary(s: LipScores) -> dict[str, Any]:
    return {
        "r": {k: round(float(v), 4) for k, v in s.r.items()},
        "closure_rate": round(s.closure_rate, 4),
        "nu_mouth_open": round(s.nu["mouth_open"], 3),
    }


def _line(s: LipScores) -> str:
    r = " / ".join(f"{s.r[p]:.3f}" for p in VISUAL_PARAMS)
    return f"r ulr/ls/mo/lcd {r}, closures {100 * s.closure_rate:.0f} %, nu(mo) {s.nu['mouth_open']:.2f}"
