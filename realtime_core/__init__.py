"""realtime_core: the pure, sans-I/O algorithms of facecast (the bottom layer; imports nothing of facecast).

numpy in, numpy out: no files, sockets, devices, clocks or prints. Streaming stages take
pushes and return what is ready; each gives the same output fed whole, sample by sample,
or in random chunks.

    errors       FacecastError (the one root of every facecast exception), ConfigError, RealtimeCoreError
    features     MFCCs at the video rate, running CMVN, context stacking, resampling, the dB level (Sec. 3)
    hmm          forward-backward/Viterbi kernels, Gaussian-mixture emissions, Baum-Welch (Sec. 4.1)
    inversion    HMM inversion, eq. 7: batch EM and the streaming forward form (Sec. 4.2)
    pipeline     SpeechToParams (the live chain: any rate -> (k, 4) params) and speech_to_params
    avmodel      AvModel: front end + CMVN statistics + HMM + streaming matrices; encode/decode bytes
    track        Track (values, channel names, fps, start) and frames_from_samples
    phones       PhonemeSegment, the phone timeline type shared by synthesis, alignment and corpora
    output       the output stage: the closed-pose floor and per-model closure band
    adaptation   speaker adaptation of a whole AvModel from enrolment speech
    synthesis    text-driven visible speech by unit selection (seed 001): EM-PCA, visemes, search, concat
    face         face models, registration, control-point projection, interpolation, rigs (Sec. 5)
    blendshapes  ARKit-52 / OVR-15 blendshape weights from the four mouth parameters
    metrics      AMSE / ACC (eq. 11-12), Pearson R and normalised MSE (paper 002 eq. 6-8)
"""

import numpy as np

from realtime_core.errors import (
    ConfigError,
    InvalidAudioError,
    InvalidFeaturesError,
    ModelFormatError,
    RealtimeCoreError,
    StreamStateError,
)

VISUAL_PARAMS: tuple[str, ...] = ("upper_lip_raise", "lip_stretch", "mouth_open", "lip_corner_depress")
"""The four mouth parameters (paper Sec. 3), in this order everywhere: files, CSV, protocol."""

CLOSED_POSE: dict[str, float] = {"mouth_open": 0.0}
"""Lower bounds of the parameters that have one: mouth_open 0 is the lips touching (the closed
pose, ``training.params``); below it one lip would pass through the other. The live path's output
stage clamps every model's estimate at these bounds (:func:`visual_floor`)."""


def visual_floor(names: tuple[str, ...]) -> np.ndarray:
    """``(len(names),)`` float64 lower bounds for parameters ``names``: :data:`CLOSED_POSE` or -inf."""
    return np.array([CLOSED_POSE.get(n, -np.inf) for n in names], dtype=np.float64)


__all__ = [
    "CLOSED_POSE",
    "VISUAL_PARAMS",
    "visual_floor",
    "ConfigError",
    "InvalidAudioError",
    "InvalidFeaturesError",
    "ModelFormatError",
    "RealtimeCoreError",
    "StreamStateError",
]
