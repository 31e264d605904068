"""Audio-to-visual conversion by HMM inversion (paper Sec. 4.2, eq. 7).

conditional  ConditionalForm: the per-component audio marginals and visual regressions
batch        hmm_inversion (EM, offline) and audio_posterior_estimate
stream       StreamConfig, StreamPlan (shared matrices), StreamingInverter (forward form, optional lag)
"""

from realtime_core.inversion.batch import HmmiConfig, HmmiResult, audio_posterior_estimate, hmm_inversion
from realtime_core.inversion.conditional import ConditionalForm
from realtime_core.inversion.stream import StreamConfig, StreamingInverter, StreamPlan

__all__ = [
    "ConditionalForm",
    "HmmiConfig",
    "HmmiResult",
    "StreamConfig",
    "StreamPlan",
    "StreamingInverter",
    "audio_posterior_estimate",
    "hmm_inversion",
]
