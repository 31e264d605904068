"""The MLP speech model (paper 002's audio-to-MUP mapper) as one object, and its file format.

A mapper file is an ``.npz`` archive (no pickle) holding ``format`` ("facecast-mlpmapper"),
``version`` (1), ``config_json`` (front end, visual names, activation, class slice, metadata), the
CMVN warm-start statistics and the :class:`MlpBank` arrays. :func:`decode_mlp_model` validates
kind, version, shapes and finiteness and names the problem; a file of another kind (for example an
HMM model given to ``--mapper mlp``) is refused with a message saying what it is. No I/O here.
"""

from __future__ import annotations

import io
import json
import zipfile
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import numpy as np

from realtime_core import VISUAL_PARAMS, visual_floor
from realtime_core.archive import AVMODEL_FORMAT, MLP_MAPPER_FORMAT, npz_arrays, npz_bytes, require_npz
from realtime_core.avmodel import (
    AvModel,
    decode_model,
    encode_model,
    frontend_from_json,
    frontend_to_json,
    validate_cmvn,
)
from realtime_core.errors import ConfigError, FacecastError, ModelFormatError
from realtime_core.features import FrontEnd, FrontEndConfig
from realtime_core.mapping.expression import STAGE_ARRAYS, ExpressionMapper, ExpressionStage
from realtime_core.mapping.mlp import MlpBank, MlpMapper, StreamingMlpMapper
from realtime_core.output import OutputStage

FORMAT = MLP_MAPPER_FORMAT
VERSION = 1
_BANK_ARRAYS = ("gmm_log_weights", "gmm_means", "gmm_vars", "w1", "b1", "w2", "b2", "hidden")


@dataclass(frozen=True, kw_only=True, eq=False)
class MlpSpeechModel:
    """bank: the GMM-selected experts; frontend / cmvn_mean / cmvn_var: how ``o_a`` is computed (as
    :class:`realtime_core.avmodel.AvModel`); visual_names: names of the served parameters;
    metadata: JSON-able training details (K, hidden units, scores, data credits); closure_band: IOD, the
    output stage's closure band (:mod:`realtime_core.output`, chosen on held-out data; 0 = off);
    expressions: paper 002's second-stage mappers (:mod:`realtime_core.mapping.expression`; None = the
    model has none, and expressions act on the four parameters by fixed offsets)."""

    bank: MlpBank
    frontend: FrontEndConfig
    cmvn_mean: np.ndarray
    cmvn_var: np.ndarray
    visual_names: tuple[str, ...] = VISUAL_PARAMS
    metadata: dict[str, Any] = field(default_factory=dict)
    closure_band: float = 0.0
    expressions: ExpressionMapper | None = None

    def __post_init__(self) -> None:
        if self.expressions is not None and (
            self.bank.readout is None or not np.allclose(self.bank.readout, self.expressions.readout)
        ):
            raise ModelFormatError("expression stages need the bank's UMUP readout (the same matrix)")
        if not 0 <= self.closure_band <= 0.1:
            raise ModelFormatError(f"closure_band must be in [0, 0.1] IOD, got {self.closure_band}")
        if self.bank.n_audio != self.frontend.audio_dim:
            raise ModelFormatError(f"MLP input width {self.bank.n_audio} != the front end's {self.frontend.audio_dim}")
        if len(self.visual_names) != self.bank.n_visual:
            raise ModelFormatError(f"{len(self.visual_names)} visual names for {self.bank.n_visual} outputs")
        validate_cmvn(self)

    @property
    def sample_rate_hz(self) -> int:
        return int(self.frontend.mfcc.sample_rate_hz)

    def front_end(self, *, kernel: str = "numba") -> FrontEnd:
        """A fresh streaming front end (kernel: "numba" or the "numpy" reference)."""
        return FrontEnd(self.frontend, cmvn_mean=self.cmvn_mean, cmvn_var=self.cmvn_var, kernel=kernel)

    @cached_property
    def _mappers(self) -> dict[str, MlpMapper]:
        return {}

    def mapper(self, dtype: str = "float32") -> MlpMapper:
        """The batch mapper (one shared plan per dtype)."""
        m = self._mappers.get(dtype)
        if m is None:
            m = self._mappers[dtype] = MlpMapper(self.bank, dtype=dtype)
        return m

    def visual_mapper(self, *, lag: int = 0, dtype: str = "float32") -> StreamingMlpMapper:
        """A fresh streaming mapper. ``lag`` must be 0: the seven-frame context is the front end's."""
        if lag != 0:
            raise ConfigError(f"the MLP mapper has no smoothing lag (its context is the front end's); got lag={lag}")
        return StreamingMlpMapper(self.mapper(dtype), output=self.output_stage, with_mups=self.expressions is not None)

    def rest_mups(self, dtype: str = "float32") -> np.ndarray:
        """``(n_mups,)`` float64: the MU parameters the mapper gives for digital silence at a stream's start (the face
        at rest as the mapper represents it; every silent frame's features are one vector, which never moves the
        CMVN). The output noise gate fades the MUPs of the rows it rests towards them, so an expression's change,
        which paper 002's second stage computes from the MUPs, is that of the silent face, not of the noise."""
        rest = self._rest.get(dtype)
        if rest is None:
            fe = self.front_end()
            oa = np.concatenate([fe.push(np.zeros(self.frontend.mfcc.window_len * 4)), fe.flush()])
            rest = self._rest[dtype] = self.mapper(dtype).mups(oa[len(oa) // 2 : len(oa) // 2 + 1])[0]
            rest.setflags(write=False)
        return rest

    @cached_property
    def _rest(self) -> dict[str, np.ndarray]:
        return {}

    @cached_property
    def output_stage(self) -> OutputStage:
        """The closed-pose floor and closure band every served estimate goes through."""
        return OutputStage(visual_floor(self.visual_names), self.closure_band)


def encode_mlp_model(model: MlpSpeechModel) -> bytes:
    """Serialise to ``.npz`` bytes (no pickle)."""
    b = model.bank
    config = {
        "frontend": frontend_to_json(model.frontend),
        "visual_names": list(model.visual_names),
        "activation": b.activation,
        "class_slice": list(b.class_slice),
        "readout": b.readout is not None,
        "closure_band": model.closure_band,
        "metadata": model.metadata,
        "expressions": [] if model.expressions is None else list(model.expressions.stages),
    }
    arrays: dict[str, np.ndarray] = {
        "format": np.array(FORMAT),
        "version": np.array(VERSION),
        "config_json": np.array(json.dumps(config, sort_keys=True)),
        "cmvn_mean": model.cmvn_mean,
        "cmvn_var": model.cmvn_var,
    }
    for name in _BANK_ARRAYS:
        arrays[name] = getattr(b, name)
    if b.readout is not None and b.readout_bias is not None:  # MlpBank checks both or neither
        arrays["readout"], arrays["readout_bias"] = b.readout, b.readout_bias
    if model.expressions is not None:
        for name, st in model.expressions.stages.items():
            for a in STAGE_ARRAYS:
                arrays[f"expr_{name}_{a}"] = getattr(st, a)
    return npz_bytes(arrays)


def decode_mlp_model(data: bytes) -> MlpSpeechModel:
    """Parse and validate ``.npz`` bytes; :class:`ModelFormatError` naming the problem."""
    arrays = npz_arrays(data, "mapper")
    kind = str(arrays["format"]) if "format" in arrays else None
    if kind == AVMODEL_FORMAT:
        raise ModelFormatError(f"this is an HMM model ({AVMODEL_FORMAT!r}), not an MLP mapper: use --mapper hmm")
    if kind != FORMAT:
        raise ModelFormatError(f"format is {kind!r}, expected {FORMAT!r}")
    if "version" not in arrays or int(arrays["version"]) != VERSION:
        v = int(arrays["version"]) if "version" in arrays else None
        raise ModelFormatError(f"MLP mapper version {v} is not supported (expected {VERSION})")
    for key in ("config_json", "cmvn_mean", "cmvn_var", *_BANK_ARRAYS):
        if key not in arrays:
            raise ModelFormatError(f"mapper archive lacks the array {key!r}")
    try:
        config = json.loads(str(arrays["config_json"]))
        has_readout = bool(config["readout"])
        bank = MlpBank(
            **{k: arrays[k] for k in _BANK_ARRAYS},
            activation=config["activation"],
            class_slice=tuple(config["class_slice"]),
            readout=arrays.get("readout") if has_readout else None,
            readout_bias=arrays.get("readout_bias") if has_readout else None,
        )
        expressions = None
        if config.get("expressions"):
            if bank.readout is None or bank.readout_bias is None:
                raise ModelFormatError("expression stages without the bank's UMUP readout")
            stages = {}
            for name in config["expressions"]:
                missing = [a for a in STAGE_ARRAYS if f"expr_{name}_{a}" not in arrays]
                if missing:
                    raise ModelFormatError(f"expression stage {name!r} lacks the array(s) {missing}")
                stages[name] = ExpressionStage(name=name, **{a: arrays[f"expr_{name}_{a}"] for a in STAGE_ARRAYS})
            expressions = ExpressionMapper(readout=bank.readout, readout_bias=bank.readout_bias, stages=stages)
        return MlpSpeechModel(
            bank=bank,
            frontend=frontend_from_json(config["frontend"]),
            cmvn_mean=arrays["cmvn_mean"],
            cmvn_var=arrays["cmvn_var"],
            visual_names=tuple(config["visual_names"]),
            metadata=config.get("metadata", {}),
            closure_band=float(config.get("closure_band", 0.0)),
            expressions=expressions,
        )
    except ModelFormatError:
        raise
    except (KeyError, TypeError, ValueError, FacecastError) as exc:
        raise ModelFormatError(f"invalid mapper configuration: {exc}") from None


def encode_speech_model(model: AvModel | MlpSpeechModel) -> bytes:
    """Either kind of :class:`realtime_core.mapping.SpeechModel` to its ``.npz`` bytes."""
    return encode_model(model) if isinstance(model, AvModel) else encode_mlp_model(model)


def decode_speech_model(data: bytes) -> AvModel | MlpSpeechModel:
    """``.npz`` bytes of either kind (told apart by their ``format``) to the model."""
    require_npz(data, "model")  # before numpy, which reads other bytes as a pickle
    try:
        kind = str(np.load(io.BytesIO(data), allow_pickle=False)["format"])
    except (ValueError, OSError, KeyError, zipfile.BadZipFile, EOFError) as exc:
        raise ModelFormatError(f"not a facecast model archive ({exc})") from None
    return decode_model(data) if kind == AVMODEL_FORMAT else decode_mlp_model(data)
