"""The trained audio-visual model as one object, and its file format (bytes in, bytes out).

A model file is an ``.npz`` archive (no pickle) holding:
  * ``format`` ("facecast-avmodel") and ``version`` (1);
  * ``config_json``: the front-end configuration (MFCC, CMVN, tc), the visual parameter
    names, and free-form training metadata (recipe, corpus, report);
  * the HMM (``startprob, transmat, weights, means, covars``, covariance type, n_audio);
  * the CMVN warm-start statistics (``cmvn_mean, cmvn_var``);
  * the precomputed streaming matrices (``center, quad, quad0, reg, reg0, phi_v, chol_vv,
    logdet_v``, see :mod:`realtime_core.inversion.conditional`);
  * optionally a learned readout (``readout_weights, readout_bias``; its sizes in ``config_json``
    under "readout"; :mod:`realtime_core.readout`).

:func:`decode_model` validates shapes, finiteness and positive-definiteness and checks
the stored streaming matrices against ones recomputed from the HMM, naming the problem
when any check fails. Writing the bytes to disk (atomically) is the caller's job: this
module does no I/O.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field, replace
from functools import cached_property
from typing import Any

import numpy as np

from realtime_core import VISUAL_PARAMS, visual_floor
from realtime_core.archive import AVMODEL_FORMAT, MLP_MAPPER_FORMAT, npz_arrays, npz_bytes
from realtime_core.errors import ModelFormatError, RealtimeCoreError
from realtime_core.features import (
    CmvnConfig,
    FrontEnd,
    FrontEndConfig,
    InputGainConfig,
    LevelNormConfig,
    MfccConfig,
)
from realtime_core.hmm.model import AvHmm
from realtime_core.inversion import (
    ConditionalForm,
    StreamConfig,
    StreamingInverter,
    StreamPlan,
)
from realtime_core.output import OutputStage
from realtime_core.readout import Readout, decode_readout, encode_readout

FORMAT = AVMODEL_FORMAT
VERSION = 1
_HMM_ARRAYS = ("startprob", "transmat", "weights", "means", "covars")
_FORM_ARRAYS = ("center", "quad", "quad0", "reg", "reg0", "phi_v", "chol_vv", "logdet_v")


@dataclass(frozen=True, kw_only=True, eq=False)
class AvModel:
    """hmm: the joint HMM over ``[o_a; o_v]``; frontend: how o_a is computed;
    cmvn_mean/cmvn_var: ``(n_feat,)`` training statistics (CMVN warm start);
    visual_names: names of the o_v dimensions; likelihood_scale: the audio-likelihood exponent
    the live path uses (chosen on held-out data, see :class:`StreamConfig`); closure_band: IOD,
    the output stage's closure band (:mod:`realtime_core.output`, chosen on held-out data; 0 = off);
    readout: the learned readout after the inversion (:mod:`realtime_core.readout`; None = eq. 7 as is);
    metadata: JSON-able training details."""

    hmm: AvHmm
    frontend: FrontEndConfig
    cmvn_mean: np.ndarray
    cmvn_var: np.ndarray
    visual_names: tuple[str, ...] = VISUAL_PARAMS
    likelihood_scale: float = 1.0
    closure_band: float = 0.0
    readout: Readout | None = None
    metadata: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.hmm.n_audio != self.frontend.audio_dim:
            raise ModelFormatError(
                f"HMM audio dimension {self.hmm.n_audio} != front end's {self.frontend.audio_dim} "
                f"((2 tc + 1) x n_feat = {2 * self.frontend.tc + 1} x {self.frontend.n_feat})"
            )
        if len(self.visual_names) != self.hmm.n_visual:
            raise ModelFormatError(f"{len(self.visual_names)} visual names for {self.hmm.n_visual} visual dims")
        validate_cmvn(self)
        if not 0 < self.likelihood_scale <= 1:
            raise ModelFormatError(f"likelihood_scale must be in (0, 1], got {self.likelihood_scale}")
        if not 0 <= self.closure_band <= 0.1:
            raise ModelFormatError(f"closure_band must be in [0, 0.1] IOD, got {self.closure_band}")
        ro = self.readout
        if ro is not None:
            sizes = (self.hmm.n_states, self.hmm.n_mix, self.hmm.n_audio, self.hmm.n_visual)
            if (ro.n_states, ro.n_mix, ro.n_audio, ro.n_visual) != sizes:
                raise ModelFormatError(
                    f"readout sizes (N, M, Da, Dv) = {(ro.n_states, ro.n_mix, ro.n_audio, ro.n_visual)} "
                    f"do not match the HMM's {sizes}"
                )

    @cached_property
    def form(self) -> ConditionalForm:
        """Precomputed inversion matrices (computed once per model)."""
        return ConditionalForm.from_model(self.hmm)

    def with_hmm(self, hmm: AvHmm) -> AvModel:
        """This model with ``hmm`` (the same sizes; speaker adaptation's audio means and weights) in place of its
        own, everything else kept: the readout re-centred (:meth:`Readout.recentred`) so that it sees the audio
        rows it was fitted on, whatever centre the new HMM's streaming matrices expand around."""
        adapted = replace(self, hmm=hmm)
        if self.readout is not None:
            adapted = replace(adapted, readout=self.readout.recentred(adapted.form.center - self.form.center))
        return adapted

    @property
    def sample_rate_hz(self) -> int:
        return int(self.frontend.mfcc.sample_rate_hz)

    def algorithmic_delay_ms(self, lag: int = 0) -> float:
        """The algorithmic delay of this model's live path with ``lag`` frames of smoothing
        (:meth:`FrontEndConfig.algorithmic_delay_ms`)."""
        return self.frontend.algorithmic_delay_ms(lag)

    def front_end(self, *, kernel: str = "numba", warp: float = 1.0) -> FrontEnd:
        """A fresh streaming front end for one utterance or live session (kernel: "numba" or the "numpy" reference).
        warp: the filterbank's frequency warp (``MfccConfig.warp``; training's vocal-tract-length copies)."""
        fe = self.frontend
        if warp != 1.0:
            fe = replace(fe, mfcc=replace(fe.mfcc, warp=warp))
        return FrontEnd(fe, cmvn_mean=self.cmvn_mean, cmvn_var=self.cmvn_var, kernel=kernel)

    @cached_property
    def _plans(self) -> dict[tuple[str, float | None], StreamPlan]:
        """Shared streaming plans by (dtype, likelihood scale): every session of this model
        reads the same matrices."""
        return {}

    def inverter(self, config: StreamConfig = StreamConfig()) -> StreamingInverter:
        """A fresh streaming inverter (with the model's likelihood scale unless ``config`` sets one)."""
        if config.likelihood_scale is None:
            config = replace(config, likelihood_scale=self.likelihood_scale)
        key = (config.dtype, config.likelihood_scale)
        plan = self._plans.get(key)
        if plan is None:
            plan = self._plans[key] = StreamPlan.build(self.form, config)
        return StreamingInverter(self.form, config=config, plan=plan, output=self.output_stage, readout=self.readout)

    @cached_property
    def visual_floor(self) -> np.ndarray:
        """``(n_visual,)`` lower bounds of the output (the closed pose; -inf where none)."""
        return visual_floor(self.visual_names)

    def visual_mapper(self, *, lag: int = 0, dtype: str = "float32") -> StreamingInverter:
        """The :class:`realtime_core.mapping.VisualMapper` of this model: a streaming inverter."""
        return self.inverter(StreamConfig(lag=lag, dtype=dtype))

    @cached_property
    def output_stage(self) -> OutputStage:
        """The closed-pose floor and closure band applied to every estimate (:mod:`realtime_core.output`)."""
        return OutputStage(self.visual_floor, self.closure_band)


def validate_cmvn(model: Any) -> None:
    """Check and store a speech model's ``cmvn_mean``/``cmvn_var`` as finite ``(n_feat,)`` float64
    (variance positive), for every model kind that carries the front end's CMVN statistics."""
    for name in ("cmvn_mean", "cmvn_var"):
        arr = np.asarray(getattr(model, name), dtype=np.float64)
        if arr.shape != (model.frontend.n_feat,) or not np.all(np.isfinite(arr)):
            raise ModelFormatError(f"{name} must be finite with shape ({model.frontend.n_feat},), got {arr.shape}")
        object.__setattr__(model, name, arr)
    if np.any(model.cmvn_var <= 0):
        raise ModelFormatError("cmvn_var must be positive")


def frontend_to_json(fe: FrontEndConfig) -> dict[str, Any]:
    mf = {k: v for k, v in asdict(fe.mfcc).items() if k not in ("window_len", "n_fft")}
    if mf.get("warp") == 1.0:  # files of unwarped models read as before the field existed
        del mf["warp"]
    return {
        "mfcc": mf,
        "cmvn": None if fe.cmvn is None else asdict(fe.cmvn),
        "tc": fe.tc,
        "energy": fe.energy,
        "silence_floor_db": fe.silence_floor_db,
        **({"level_norm": asdict(fe.level_norm)} if fe.level_norm is not None else {}),
        **({"input_gain": asdict(fe.input_gain)} if fe.input_gain is not None else {}),
    }


def frontend_from_json(d: dict[str, Any]) -> FrontEndConfig:
    return FrontEndConfig(
        mfcc=MfccConfig(**d["mfcc"]),
        cmvn=None if d.get("cmvn") is None else CmvnConfig(**d["cmvn"]),
        tc=int(d["tc"]),
        energy=bool(d.get("energy", False)),
        # Models written before the gate existed were trained without it.
        silence_floor_db=d.get("silence_floor_db"),
        # Models written before level normalisation use absolute levels.
        level_norm=None if d.get("level_norm") is None else LevelNormConfig(**d["level_norm"]),
        # Models written before the run-time gain stage take the samples as given.
        input_gain=None if d.get("input_gain") is None else _input_gain_from_json(d["input_gain"]),
    )


def _input_gain_from_json(d: dict[str, Any]) -> InputGainConfig:
    return InputGainConfig(**{**d, "tracker": LevelNormConfig(**d["tracker"])})


def encode_model(model: AvModel) -> bytes:
    """Serialise to ``.npz`` bytes (no pickle)."""
    config = {
        "frontend": frontend_to_json(model.frontend),
        "visual_names": list(model.visual_names),
        "likelihood_scale": model.likelihood_scale,
        "closure_band": model.closure_band,
        "covariance_type": model.hmm.covariance_type,
        "n_audio": model.hmm.n_audio,
        "metadata": model.metadata,
    }
    ro_arrays: dict[str, np.ndarray] = {}
    if model.readout is not None:
        config["readout"], ro_arrays = encode_readout(model.readout)
    arrays: dict[str, np.ndarray] = {
        "format": np.array(FORMAT),
        "version": np.array(VERSION),
        "config_json": np.array(json.dumps(config, sort_keys=True)),
        "cmvn_mean": model.cmvn_mean,
        "cmvn_var": model.cmvn_var,
    }
    for name in _HMM_ARRAYS:
        arrays[name] = getattr(model.hmm, name)
    for name in _FORM_ARRAYS:
        arrays[name] = getattr(model.form, name)
    arrays.update(ro_arrays)
    return npz_bytes(arrays)


def decode_model(data: bytes) -> AvModel:
    """Parse and validate ``.npz`` bytes; raises :class:`ModelFormatError` naming the problem."""
    arrays = npz_arrays(data, "model")
    # The kind first: a mapper file given as a model was refused for lacking 'startprob'.
    kind = str(arrays["format"]) if "format" in arrays else None
    if kind == MLP_MAPPER_FORMAT:
        raise ModelFormatError(f"this is an MLP mapper ({MLP_MAPPER_FORMAT!r}), not an HMM model: use --mapper mlp")
    if kind is not None and kind != FORMAT:
        raise ModelFormatError(f"format is {kind!r}, expected {FORMAT!r}")
    for key in ("format", "version", "config_json", "cmvn_mean", "cmvn_var", *_HMM_ARRAYS, *_FORM_ARRAYS):
        if key not in arrays:
            raise ModelFormatError(f"model archive lacks the array {key!r}")
    if int(arrays["version"]) != VERSION:
        raise ModelFormatError(f"model version {int(arrays['version'])} is not supported (expected {VERSION})")
    try:
        config = json.loads(str(arrays["config_json"]))
        frontend = frontend_from_json(config["frontend"])
        hmm = AvHmm(
            **{k: arrays[k] for k in _HMM_ARRAYS},
            covariance_type=config["covariance_type"],
            n_audio=int(config["n_audio"]),
        )
        model = AvModel(
            hmm=hmm,
            frontend=frontend,
            cmvn_mean=arrays["cmvn_mean"],
            cmvn_var=arrays["cmvn_var"],
            visual_names=tuple(config["visual_names"]),
            likelihood_scale=float(config.get("likelihood_scale", 1.0)),
            closure_band=float(config.get("closure_band", 0.0)),  # 0: models from before the band
            readout=decode_readout(config["readout"], arrays) if config.get("readout") is not None else None,
            metadata=config.get("metadata", {}),
        )
    except ModelFormatError:
        raise
    except (KeyError, TypeError, ValueError, RealtimeCoreError) as exc:
        raise ModelFormatError(f"invalid model configuration: {exc}") from None
    form = model.form
    for name in _FORM_ARRAYS:
        stored, fresh = arrays[name], getattr(form, name)
        if stored.shape != fresh.shape:
            raise ModelFormatError(f"stored streaming matrix {name} has shape {stored.shape}, expected {fresh.shape}")
        if not np.allclose(stored, fresh, rtol=1e-6, atol=1e-8):
            raise ModelFormatError(f"stored streaming matrix {name} does not match the HMM it was saved with")
    return model
