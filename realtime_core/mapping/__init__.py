"""Audio-to-visual mappers behind one streaming interface (:class:`VisualMapper`).

interface  the VisualMapper / SpeechModel protocols the HMM inverter and the MLP mapper share
mlp        paper 002 Sec. VI-A: a Gaussian-mixture classifier picks one of K small MLPs
expression paper 002 Sec. VI-B: the second-stage MLPs (UMUPs -> UMUPs + EMUPs) at run time
model      the MLP speech model and its versioned ``.npz`` format
"""

from realtime_core.mapping.expression import ExpressionMapper, ExpressionStage
from realtime_core.mapping.interface import MAPPER_KINDS, SpeechModel, VisualMapper
from realtime_core.mapping.mlp import MlpBank, MlpMapper, StreamingMlpMapper
from realtime_core.mapping.model import (
    MlpSpeechModel,
    decode_mlp_model,
    decode_speech_model,
    encode_mlp_model,
    encode_speech_model,
)

__all__ = [
    "MAPPER_KINDS",
    "ExpressionMapper",
    "ExpressionStage",
    "MlpBank",
    "MlpMapper",
    "MlpSpeechModel",
    "SpeechModel",
    "StreamingMlpMapper",
    "VisualMapper",
    "decode_mlp_model",
    "decode_speech_model",
    "encode_mlp_model",
    "encode_speech_model",
]
