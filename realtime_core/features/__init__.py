"""Audio features at the video rate (paper Sec. 3), each a push/flush streaming stage or a pure function.

mfcc      MfccConfig, MfccStream (MFCCs on the exact 30 fps grid), mfcc (whole signal), mel_filterbank,
          frame_log_energy_db / loudness_db (the one per-frame dB level)
cmvn      CmvnConfig, RunningCmvn (warm-started, speech-gated running mean/variance), mel_level_db
gain      InputGainConfig, InputGain (run-time input gain to the training speech level, causal)
level     LevelNormConfig, LevelTracker (the speech peak and noise floor per stream: gain-invariant c0)
noisegate NoiseGateConfig, NoiseGate (a room's steady noise alone fades the output to the rest pose)
context   ContextStacker, stack_context (+-tc frames of context)
frontend  FrontEndConfig, FrontEnd (MFCC -> CMVN -> context), extract_features, raw_mfcc_with_level
resample  StreamingResampler (any input rate -> the model's, chunk-invariant), resample_audio (whole signal)
"""

from realtime_core.features.cmvn import CmvnConfig, RunningCmvn, mel_level_db
from realtime_core.features.context import ContextStacker, stack_context
from realtime_core.features.frontend import FrontEnd, FrontEndConfig, extract_features, raw_mfcc_with_level
from realtime_core.features.gain import InputGain, InputGainConfig
from realtime_core.features.level import LevelNormConfig, LevelTracker
from realtime_core.features.mfcc import (
    MfccConfig,
    MfccStream,
    frame_log_energy_db,
    loudness_db,
    mel_filterbank,
    mfcc,
)
from realtime_core.features.noisegate import NoiseGate, NoiseGateConfig

__all__ = [
    "CmvnConfig",
    "ContextStacker",
    "FrontEnd",
    "FrontEndConfig",
    "InputGain",
    "InputGainConfig",
    "LevelNormConfig",
    "LevelTracker",
    "MfccConfig",
    "MfccStream",
    "NoiseGate",
    "NoiseGateConfig",
    "RunningCmvn",
    "extract_features",
    "frame_log_energy_db",
    "loudness_db",
    "mel_filterbank",
    "mel_level_db",
    "mfcc",
    "raw_mfcc_with_level",
    "stack_context",
]
