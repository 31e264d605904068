"""Audio features at the video rate (paper Sec. 3): MFCC, running CMVN, context stacking."""

from realtime_core.features.cmvn import CmvnConfig, RunningCmvn, mel_level_db
from realtime_core.features.context import ContextStacker, stack_context
from realtime_core.features.frontend import FrontEnd, FrontEndConfig, extract_features, raw_mfcc_with_level
from realtime_core.features.mfcc import MfccConfig, MfccStream, frame_log_energy_db, mel_filterbank, mfcc

__all__ = [
    "CmvnConfig", "ContextStacker", "FrontEnd", "FrontEndConfig", "MfccConfig", "MfccStream",
    "RunningCmvn", "extract_features", "frame_log_energy_db", "mel_filterbank", "mel_level_db",
    "mfcc", "raw_mfcc_with_level", "stack_context",
]
