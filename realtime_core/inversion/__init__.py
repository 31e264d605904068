"""Audio-to-visual conversion by HMM inversion (paper Sec. 4.2, eq. 7)."""

from realtime_core.inversion.batch import HmmiConfig, HmmiResult, audio_posterior_estimate, hmm_inversion
from realtime_core.inversion.conditional import ConditionalForm
from realtime_core.inversion.stream import StreamConfig, StreamingInverter, StreamPlan

__all__ = [
    "ConditionalForm", "HmmiConfig", "HmmiResult", "StreamConfig", "StreamPlan", "StreamingInverter",
    "audio_posterior_estimate", "hmm_inversion",
]
