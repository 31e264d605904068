"""From corpus utterances to a trained audio-visual model, and its evaluation.

Stages:
  1. every utterance is resampled to the model rate (scipy's polyphase resampler);
  2. CMVN statistics: mean/variance of raw MFCCs over the *speech* frames of the training
     set (frames above the CMVN gate) -- these become the model's warm-start statistics;
  3. o_a: the same streaming front end the live server runs (MFCC -> running CMVN warm-started
     with those statistics -> context), so training sees exactly the live features;
  4. the joint sequences ``[o_a; o_v]`` train the HMM by Baum-Welch (k-means initialisation).

Evaluation runs the exact live path (:func:`realtime_core.pipeline.speech_to_params`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field

import numpy as np

from realtime_core import VISUAL_PARAMS
from realtime_core.avmodel import AvModel
from realtime_core.features import (
    CmvnConfig,
    FrontEndConfig,
    LevelNormConfig,
    MfccConfig,
    extract_features,
    raw_mfcc_with_level,
)
from realtime_core.features.resample import resample_audio
from realtime_core.hmm import AvHmm, TrainConfig, TrainResult, baum_welch, init_model
from realtime_core.metrics import acc, amse, pearson_per_param
from realtime_core.pipeline import speech_to_params
from training.corpus import Utterance
from training.errors import ConfigError

IterationFn = Callable[[int, float, AvModel], None]
"""Called after each E-step with (iteration, objective per frame, the model scored): the
caller draws progress and writes checkpoints."""


@dataclass(frozen=True, kw_only=True)
class TrainRecipe:
    """sample_rate_hz: model rate (inputs are resampled to it); n_ceps; tc (context);
    window_hops: MFCC analysis window in video hops (with tc it sets the algorithmic delay,
    :meth:`realtime_core.features.FrontEndConfig.algorithmic_delay_ms`); hmm: Baum-Welch settings (N, M,
    covariance type, priors, iterations, seed);
    energy: use c0 as a feature too; likelihood_scale: the live path's audio-likelihood
    exponent, stored in the model."""

    sample_rate_hz: int = 16000
    n_ceps: int = 11
    tc: int = 3
    window_hops: float = 2.0
    energy: bool = True
    cmvn: CmvnConfig = field(default_factory=CmvnConfig)
    level_norm: LevelNormConfig | None = None
    hmm: TrainConfig = field(default_factory=lambda: TrainConfig(n_states=16, n_mix=3, n_iter=25, tol=5e-4))
    likelihood_scale: float = 0.1

    @property
    def frontend(self) -> FrontEndConfig:
        return FrontEndConfig(
            mfcc=MfccConfig(sample_rate_hz=self.sample_rate_hz, n_ceps=self.n_ceps, window_hops=self.window_hops),
            cmvn=self.cmvn,
            tc=self.tc,
            energy=self.energy,
            level_norm=self.level_norm,
        )

    def as_json(self) -> dict:
        h = self.hmm
        return {
            "sample_rate_hz": self.sample_rate_hz,
            "n_ceps": self.n_ceps,
            "tc": self.tc,
            "window_hops": self.window_hops,
            "energy": self.energy,
            "n_states": h.n_states,
            "n_mix": h.n_mix,
            "covariance_type": h.covariance_type,
            "n_iter": h.n_iter,
            "tol": h.tol,
            "covar_prior_weight": h.covar_prior_weight,
            "covar_prior_scale": h.covar_prior_scale,
            "seed": h.seed,
            "likelihood_scale": self.likelihood_scale,
            **({"level_norm": asdict(self.level_norm), "cmvn_gate_db": self.cmvn.gate_db} if self.level_norm else {}),
        }


def cmvn_statistics(audio: Sequence[np.ndarray], frontend: FrontEndConfig) -> tuple[np.ndarray, np.ndarray]:
    """Mean and variance ``(n_feat,)`` of raw features over speech frames (level >= gate)."""
    gate = frontend.cmvn.gate_db if frontend.cmvn is not None else -np.inf
    rows = []
    for x in audio:
        ceps, level = raw_mfcc_with_level(x, frontend)
        rows.append(ceps[level >= gate])
    allc = np.concatenate(rows)
    if len(allc) < 10:
        raise ConfigError(f"only {len(allc)} speech frames in the training audio: too little to train on")
    return allc.mean(axis=0), np.maximum(allc.var(axis=0), 1e-6)


def utterance_audio(utt: Utterance, rate_hz: int) -> np.ndarray:
    return resample_audio(utt.samples, utt.sample_rate_hz, rate_hz)


def joint_sequence(
    audio: np.ndarray, params: np.ndarray, frontend: FrontEndConfig, mean: np.ndarray, var: np.ndarray
) -> np.ndarray:
    """``(T, Da + 4)`` joint observations of one utterance: ``audio (n,)`` at the model rate and
    its ``params (n_frames, 4)`` (T trimmed to the shorter track)."""
    oa = extract_features(audio, frontend, cmvn_mean=mean, cmvn_var=var)
    T = min(len(oa), len(params))
    return np.hstack([oa[:T], params[:T]])


def train_av_model(
    utterances: Sequence[Utterance],
    recipe: TrainRecipe,
    *,
    on_iteration: IterationFn | None = None,
    start: AvHmm | None = None,
    metadata: dict | None = None,
    visual_names: tuple[str, ...] = VISUAL_PARAMS,
) -> tuple[AvModel, TrainResult]:
    """Train on ``utterances``. ``start``: resume EM from this HMM instead of k-means.

    visual_names: names of the columns of every ``u.params`` (the four mouth parameters by default;
    Motion-Unit parameters for the MU models)."""
    if not utterances:
        raise ConfigError("no training utterances")
    fe = recipe.frontend
    audio = [utterance_audio(u, recipe.sample_rate_hz) for u in utterances]
    mean, var = cmvn_statistics(audio, fe)
    seqs = [joint_sequence(x, u.params, fe, mean, var) for x, u in zip(audio, utterances)]
    hmm0 = start if start is not None else init_model(seqs, n_audio=fe.audio_dim, config=recipe.hmm)
    meta = {
        "recipe": recipe.as_json(),
        "train_utterances": len(utterances),
        "train_frames": int(sum(len(s) for s in seqs)),
        **(metadata or {}),
    }

    def wrap(hmm: AvHmm, extra: dict) -> AvModel:
        return AvModel(
            hmm=hmm,
            frontend=fe,
            cmvn_mean=mean,
            cmvn_var=var,
            visual_names=visual_names,
            likelihood_scale=recipe.likelihood_scale,
            metadata={**meta, **extra},
        )

    def progress(it: int, objective: float, hmm: AvHmm) -> None:
        if on_iteration is not None:
            on_iteration(it, objective, wrap(hmm, {"iteration": it, "objective_per_frame": objective}))

    result = baum_welch(seqs, hmm0, config=recipe.hmm, progress=progress)
    return wrap(result.model, {"em_history": result.history, "converged": result.converged}), result


def split_by_utterance(utterances: Sequence[Utterance], *, held_out: float = 0.2, seed: int = 0):
    """80/20 (by default) split by utterance, reproducible from ``seed``: ``(train, test)``."""
    idx = np.random.default_rng(seed).permutation(len(utterances))
    n_test = max(1, int(round(held_out * len(utterances))))
    test = sorted(idx[:n_test].tolist())
    return [utterances[i] for i in sorted(idx[n_test:].tolist())], [utterances[i] for i in test]


@dataclass(frozen=True)
class Evaluation:
    """eps (eq. 11) and rho (eq. 12) over all test frames pooled, Pearson r per parameter,
    and the tracks (per utterance: truth, estimate) for plots."""

    eps: float
    rho: float
    r_per_param: dict
    tracks: list = field(repr=False, default_factory=list)


def evaluate(model: AvModel, utterances: Sequence[Utterance], *, mode: str = "stream") -> Evaluation:
    truth, est, tracks = [], [], []
    for u in utterances:
        e = speech_to_params(model, utterance_audio(u, model.sample_rate_hz), mode=mode)
        T = min(len(e), len(u.params))
        truth.append(u.params[:T])
        est.append(e[:T])
        tracks.append((u.id, u.params[:T], e[:T]))
    t, e = np.concatenate(truth), np.concatenate(est)
    r = pearson_per_param(t, e)
    return Evaluation(eps=amse(t, e), rho=acc(t, e), r_per_param=dict(zip(VISUAL_PARAMS, map(float, r))), tracks=tracks)
