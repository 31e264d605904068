"""Speaker adaptation of a whole :class:`AvModel` from enrolment speech (samples in, model out).

The enrolment recordings go through the model's own front end (MFCC -> CMVN -> context, as
the live path computes them), then :func:`realtime_core.hmm.adapt.map_adapt` re-estimates the
audio means and mixture weights. The result is a new :class:`AvModel` (same front end, CMVN
statistics, visual side and learned readout, the readout re-centred so it sees the audio rows it was
fitted on: :meth:`AvModel.with_hmm`) whose streaming matrices are recomputed from the adapted HMM when
first used. No I/O: reading the audio and saving the model are the caller's.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from realtime_core.avmodel import AvModel
from realtime_core.errors import NotSpeechError
from realtime_core.features.gain import DIGITAL_SILENCE_PEAK
from realtime_core.features.mfcc import as_float_samples
from realtime_core.hmm.adapt import (
    AdaptConfig,
    AdaptResult,
    audio_log_likelihood,
    map_adapt,
)

MIN_ENROL_S = 1.0
"""s: the least speech an adaptation takes (``facecast adapt`` and a session's ``enrol`` alike); 30-60 s is the
intended amount. Under a second a few dozen frames would move the components they visit towards one syllable."""

MAX_ENROL_S = 120.0
"""s: the most speech a session's ``enrol`` takes (and ``facecast send --enrol`` sends); 30-60 s is the intended
amount."""

MIN_VISITED_SHARE = 0.25
"""The least share of the model's audio components (states x mixtures) an enrolment of :data:`CHECK_SPEECH_FROM_S`
or more must visit (occupancy over one frame) to be taken as speech. Measured with the shipped models (48
components): read speech of 7-220 s visits 21-23 of them (ARCTIC, LibriVox, LJ Speech), 3 s of GRID 17; 40 s of a
pure tone, white or pink noise, a three-note chord or music 1-5, 5 s of speech then 40 s of a tone 6. Adapting to
those would pull a few components onto the sound and leave the voice unadapted, so it is refused."""

CHECK_SPEECH_FROM_S = 10.0
"""s of sound from which an enrolment is checked to sound like speech: a short take of real speech visits few
components (1-1.5 s of LJ Speech or LibriVox 2-5 of 48, ARCTIC 8), as few as a tone."""


def enrolment_features(model: AvModel, recordings: Sequence[np.ndarray]) -> list[np.ndarray]:
    """``(n,)`` samples at ``model.sample_rate_hz`` each -> ``(T_i, Da)`` audio features, each
    recording through a fresh front end (as a live session would see it), split where frames of digital
    silence (a window's peak under :data:`realtime_core.features.gain.DIGITAL_SILENCE_PEAK`) are left out: never in
    a live microphone's input, 30 s of zeros between 9 s of speech pulled the adaptation onto them (audio
    log-likelihood per frame -43 -> +212)."""
    mfcc = model.frontend.mfcc
    out = []
    for samples in recordings:
        x = as_float_samples(samples)
        fe = model.front_end()
        oa = np.concatenate([fe.push(x), fe.flush()])
        if not len(oa):
            continue
        starts = (np.arange(len(oa)) * int(mfcc.sample_rate_hz)) // int(mfcc.frame_rate_hz)  # frame_start(k)
        peaks = np.array([np.abs(x[a : a + mfcc.window_len]).max(initial=0.0) for a in starts])
        edges = np.flatnonzero(np.diff(np.concatenate([[0], (peaks >= DIGITAL_SILENCE_PEAK).astype(int), [0]])))
        out += [oa[a:b] for a, b in zip(edges[::2], edges[1::2], strict=True)]
    return out


def adapt_av_model(
    model: AvModel, recordings: Sequence[np.ndarray], *, config: AdaptConfig | None = None
) -> tuple[AvModel, AdaptResult]:
    """MAP-adapt ``model`` to the voice in ``recordings`` (samples at the model's rate, no
    transcript). Returns the adapted model (with an ``adaptation`` entry in its metadata) and
    the EM details. No recordings (or no frames) returns ``model`` itself; recordings that do not
    sound like speech (:data:`MIN_VISITED_SHARE`) raise :class:`NotSpeechError`."""
    config = config or AdaptConfig()
    feats = enrolment_features(model, recordings)
    result = map_adapt(model.hmm, feats, config=config)
    if result.n_frames == 0:
        return model, result
    before = audio_log_likelihood(model.hmm, feats) / result.n_frames
    after = audio_log_likelihood(result.model, feats) / result.n_frames
    # map_adapt fills occupancy whenever it saw frames (n_frames > 0 here)
    visited = int(np.sum(result.occupancy > 1.0)) if result.occupancy is not None else 0
    n_components = model.hmm.n_states * model.hmm.n_mix
    fps = model.frontend.mfcc.frame_rate_hz
    if result.n_frames >= CHECK_SPEECH_FROM_S * fps and visited < MIN_VISITED_SHARE * n_components:
        raise NotSpeechError(
            f"it does not sound like speech: {visited} of {n_components} audio components visited "
            "(a tone, noise or music?)"
        )
    meta = dict(model.metadata)
    meta["adaptation"] = {
        "method": "MAP (Gauvain & Lee) of audio means and mixture weights on the audio marginal",
        "frames": result.n_frames,
        "seconds": round(result.n_frames / model.frontend.mfcc.frame_rate_hz, 2),
        "relevance": config.relevance,
        "weight_relevance": config.weight_relevance,
        "iterations": len(result.history) - 1,
        "audio_loglik_per_frame": [round(before, 4), round(after, 4)],
        "components_visited": visited,
    }
    return replace(model.with_hmm(result.model), metadata=meta), result
