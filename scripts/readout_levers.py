"""Cheap levers on the default model's learned readout, scored on s1 val (issue 10, eighth round).

    python scripts/readout_levers.py [NAME[@SEED] ...]     # default: every candidate below, in this order

``@SEED`` fits the candidate's nets with MLP seeds SEED, SEED + 1, ... instead of 0, 1, ... (the ninth round
scores ``R0 W4K8 R0@3 W4K8@3``: seed sets A = 0-2 and B = 3-5).

The shipped HMM (`assets/data/default_model.npz`) is traced once over the 716 train sentences plus the
shipped recipe's 4 vocal-tract-length copies of each (warps 0.85-1.18, `--vtlp-seed 1`: 322,200 frames)
and the 93 val sentences (`training.readout.trace_clips`, `vtlp_copies`); every candidate is fitted on
those traces, its closure band re-chosen on val as `facecast readout` does (the highest r(mouth_open)
keeping >= 91.5 % of the 110 /p b m/), and scored on val and on the real speech of other voices (6 clips,
rules truth, `training.reallips.score_real_speech`). The test split is never looked at. One JSON line per
candidate goes to stdout. Candidates (each the shipped form 5:state:64x3:1e-3 but for the change named):

- ``shipped``: the readout in the model file, as stored (the reference);
- ``R0``: the shipped recipe refitted on today's traces (the refit's own noise);
- ``W2``, ``W4``: lip_stretch's loss weight 2 or 4 (``ReadoutSpec.loss_weight``: its target scaled by
  sqrt(w) in the fit, the output layer scaled back, so the live path's readout form is unchanged);
- ``K8``, ``K12``: 8 or 12 causal taps of the eq. 7 estimate; ``W4K8``: both;
- ``H128``: 128 units per net; ``A4``: L2 penalty 1e-4; ``E6``: 6 nets (seeds 0-5) averaged;
- ``AT``: the audio rows of frames t-3 and t-6 added to the inputs (the readout's audio window widened
  back from t-3..t+3 to t-9..t+3); not a form the live path runs, so scored here through scikit-learn.
"""

from __future__ import annotations

import json
import sys
import time
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from threadpoolctl import threadpool_limits

from assets.modelfile import load_model
from assets.shared import shared_data_root
from realtime_core import VISUAL_PARAMS
from realtime_core.avmodel import AvModel
from realtime_core.features import loudness_db
from realtime_core.features.resample import resample_audio
from realtime_core.output import OutputStage
from training.readout import (
    ReadoutSpec,
    Traced,
    VtlpConfig,
    _features,
    estimates,
    fit_readout,
    mlp_regressor,
    trace_clips,
    vtlp_copies,
)
from training.readout import choose_band as readout_choose_band
from training.reallips import LipScores, real_speech_clips, s1_clips, score_lips, score_real_speech

BANDS = (0.02, 0.025, 0.03, 0.035, 0.04, 0.045, 0.05)
MIN_CLOSURE = 0.915
CANDIDATES = ("shipped", "R0", "W2", "W4", "K8", "K12", "W4K8", "H128", "A4", "E6", "AT")
AUDIO_LAGS = (3, 6)


def spec_of(name: str) -> ReadoutSpec:
    """``NAME[@SEED]`` -> its candidate (the shipped form but for the change named; MLP seeds from SEED, default 0)."""
    name, _, seed = name.partition("@")
    taps = {"K8": 8, "K12": 12, "W4K8": 8}.get(name, 5)
    hidden = 128 if name == "H128" else 64
    return ReadoutSpec(
        taps=taps,
        posteriors="state",
        hidden=hidden,
        alpha=1e-4 if name == "A4" else 1e-3,
        ensemble=6 if name == "E6" else 3,
        seed=int(seed or 0),
        loss_weight={"lip_stretch": {"W2": 2.0, "W4": 4.0, "W4K8": 4.0}.get(name, 1.0)},
    )


@dataclass
class AudioTaps:
    """The ``AT`` candidate: scikit-learn nets on the readout's inputs plus past audio rows."""

    spec: ReadoutSpec
    scaler: Any
    nets: list

    @staticmethod
    def inputs(model: AvModel, c: Traced, spec: ReadoutSpec) -> np.ndarray:
        T = len(c.audio)
        past = [np.concatenate([np.repeat(c.audio[:1], lag, axis=0), c.audio])[:T] for lag in AUDIO_LAGS]
        return np.concatenate([_features(spec, model, [c]), *past], axis=1)

    @classmethod
    def fit(cls, model: AvModel, train: list[Traced], spec: ReadoutSpec) -> AudioTaps:
        from sklearn.preprocessing import StandardScaler

        phi = np.concatenate([cls.inputs(model, c, spec) for c in train])
        y = np.concatenate([c.truth for c in train])
        scaler = StandardScaler().fit(phi)
        nets = [mlp_regressor(spec, k).fit(scaler.transform(phi), y) for k in range(spec.ensemble)]
        return cls(spec, scaler, nets)

    def apply(self, model: AvModel, c: Traced) -> np.ndarray:
        phi = self.scaler.transform(self.inputs(model, c, self.spec))
        return np.mean([net.predict(phi) for net in self.nets], axis=0)

    def items(self, model: AvModel, clips: list[Traced], band: float) -> list:
        stage = OutputStage(model.visual_floor, band)
        return [(c.name, c.truth, stage(self.apply(model, c).copy()), c.loudness, c.spans) for c in clips]

    def real_speech(self, model: AvModel, clips: list, band: float) -> LipScores:
        """The real-speech clips through the same live-path trace as the train clips."""
        inv = model.inverter()
        traced = []
        for name, x, rate, truth, spans in clips:
            x = np.asarray(x, np.float64)
            x = x.mean(axis=1) if x.ndim > 1 else x
            if rate != model.sample_rate_hz:
                x = resample_audio(x, rate, model.sample_rate_hz)
            fe = model.front_end()
            raw, post, audio = inv.trace(np.concatenate([fe.push(x), fe.flush()]))
            T = min(len(raw), len(truth))
            loud = loudness_db(x.astype(np.float32), model.sample_rate_hz, T)
            traced.append(Traced(name, truth[:T], raw[:T], post[:T], audio[:T], loud, list(spans)))
        return score_lips(self.items(model, traced, band))


def summary(s: LipScores) -> dict[str, Any]:
    return {
        "r": {p: round(float(s.r[p]), 4) for p in VISUAL_PARAMS},
        "closures": f"{round(s.closure_rate * s.n_closures)}/{s.n_closures}",
        "nu_mouth_open": round(float(s.nu["mouth_open"]), 3),
    }


def choose_band(score) -> tuple[float, LipScores]:
    """``facecast readout``'s band rule (:func:`training.readout.choose_band`) over BANDS at MIN_CLOSURE."""
    return readout_choose_band(score, bands=BANDS, min_closure=MIN_CLOSURE)


def main(names: list[str]) -> None:
    t0 = time.time()
    shipped = load_model(None)
    base = replace(shipped, readout=None)
    train_clips, val_clips = s1_clips("train"), s1_clips("val")
    val = trace_clips(base, val_clips)
    speech = real_speech_clips(shared_data_root() / "speech")
    vtlp = VtlpConfig(copies=4, warp_range=(0.85, 1.18), seed=1)
    train: list[Traced] = []
    for name in names:
        row: dict[str, Any] = {"name": name}
        if name == "shipped":
            band = shipped.closure_band
            s = score_lips(estimates(base, val, shipped.readout, band))
            real = score_real_speech(shipped, speech)
        else:
            if not train:
                train = trace_clips(base, train_clips) + vtlp_copies(base, train_clips, vtlp)
            spec = spec_of(name)
            if name.partition("@")[0] == "AT":
                at = AudioTaps.fit(base, train, spec)
                band, s = choose_band(lambda b, at=at: score_lips(at.items(base, val, b)))
                real = at.real_speech(base, speech, band)
                row["epochs"] = [int(net.n_iter_) for net in at.nets]
            else:
                ro = fit_readout(base, train, spec)
                band, s = choose_band(lambda b, ro=ro: score_lips(estimates(base, val, ro, b)))
                real = score_real_speech(replace(base, readout=ro, closure_band=band), speech)
                row["epochs"] = ro.metadata["epochs"]
        row.update(band=band, val=summary(s), real_speech=summary(real), seconds=round(time.time() - t0))
        print(json.dumps(row), flush=True)


if __name__ == "__main__":
    with threadpool_limits(1):  # as `facecast readout`: one BLAS thread fixes the fits
        main(sys.argv[1:] or list(CANDIDATES))
