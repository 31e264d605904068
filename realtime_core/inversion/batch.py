"""Batch HMM inversion (paper Sec. 4.2, eq. 2-7) for offline use.

Theory of operation
-------------------
HMMI seeks ``O_v = argmax P(O_a, O_v | lambda)``. Treating O_v as a parameter and the
state/mixture sequence as hidden, EM alternates (i) joint posteriors
``g_t(j, k) = P(q_t = j, k_t = k | O_a, O_v)`` by forward-backward on the joint
likelihoods, and (ii) eq. 7, the Phi_v-weighted average of conditional means. EM never
lowers ``log P(O_a, O_v)``; iteration stops when the gain per frame is below ``tol``.

Because ``log N([a; v]) = log N_a(a) + log N(v; m(a), S)``, the expensive audio-marginal
part is computed once per utterance; each iteration only redoes the Dv-dimensional
conditional term.

Initialisation: the paper starts from a random visual sequence, which falls into poor
local optima when the audio is ambiguous. By default we start from the *audio-posterior
estimate*: posteriors from the audio-marginal likelihoods alone (forward-backward, or
forward-only filtering, which is what the streaming path computes), combined by eq. 7.
``init="random"`` reproduces the paper.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.special import logsumexp

from realtime_core.errors import ConfigError
from realtime_core.hmm.kernels import forward_backward, log_forward
from realtime_core.inversion.conditional import ConditionalForm


def _component_resp(gamma: np.ndarray, logc: np.ndarray, log_b: np.ndarray) -> np.ndarray:
    """State posteriors ``(T, N)`` x within-state mixture posteriors -> ``(T, C)``."""
    with np.errstate(under="ignore"):
        return (gamma[:, :, None] * np.exp(logc - log_b[:, :, None])).reshape(len(gamma), -1)


def audio_posterior_estimate(
    form: ConditionalForm, oa: np.ndarray, *, smoothing: str = "forward-backward", likelihood_scale: float = 1.0
) -> np.ndarray:
    """Visual estimate from audio-only posteriors: ``oa (T, Da) -> o_v (T, Dv)``.

    smoothing: "forward-backward" (offline: each frame sees the whole utterance) or
    "forward" (causal filtering: exactly the streaming path with lag 0).
    likelihood_scale: exponent on the audio likelihoods (see :class:`StreamConfig`).
    """
    if smoothing not in ("forward-backward", "forward"):
        raise ConfigError(f"smoothing must be 'forward-backward' or 'forward', got {smoothing!r}")
    ll_a, cond = form.audio_terms(np.asarray(oa, dtype=np.float64))
    logc = likelihood_scale * ll_a.reshape(len(oa), form.n_states, form.n_mix) + form.log_weights
    log_b = logsumexp(logc, axis=2)
    if smoothing == "forward":
        la, _ = log_forward(form.log_startprob, form.log_transmat, log_b)
        gamma = np.exp(la - logsumexp(la, axis=1, keepdims=True))
    else:
        gamma = forward_backward(form.log_startprob, form.log_transmat, log_b)[0]
    return form.combine(_component_resp(gamma, logc, log_b), cond)


@dataclass(frozen=True, kw_only=True)
class HmmiConfig:
    """init: "audio-posterior" (default) or "random" (the paper's); max_iter; tol: stop when
    the joint log-likelihood gains less than this per frame; seed: for init="random"."""

    init: str = "audio-posterior"
    max_iter: int = 50
    tol: float = 1e-4
    seed: int = 0

    def __post_init__(self) -> None:
        if self.init not in ("audio-posterior", "random"):
            raise ConfigError(f"init must be 'audio-posterior' or 'random', got {self.init!r}")
        if self.max_iter < 0 or self.tol < 0:
            raise ConfigError("max_iter and tol must be >= 0")


@dataclass(frozen=True)
class HmmiResult:
    """visual: ``(T, Dv)`` estimate; history: ``log P(O_a, O_v) / T`` at each iterate
    (non-decreasing); n_iter: eq.-7 updates applied."""

    visual: np.ndarray
    history: list[float] = field(default_factory=list)
    n_iter: int = 0


def hmm_inversion(form: ConditionalForm, oa: np.ndarray, *, config: HmmiConfig = HmmiConfig()) -> HmmiResult:
    """Batch HMMI by EM on eq. 7. ``oa (T, Da)`` -> :class:`HmmiResult`."""
    oa = np.asarray(oa, dtype=np.float64)
    T = len(oa)
    ll_a, cond = form.audio_terms(oa)
    if config.init == "random":
        rng = np.random.default_rng(config.seed)
        # Random frames drawn around the model's overall visual mean and spread.
        w = np.exp(form.log_weights).reshape(-1) / form.n_states
        mean_v = np.einsum("c,tci->i", w, cond) / T
        spread = np.sqrt(np.maximum(np.einsum("cii->ci", np.linalg.inv(form.phi_v)).mean(axis=0), 1e-12))
        ov = mean_v + spread * rng.standard_normal((T, form.n_visual))
    else:
        ov = audio_posterior_estimate(form, oa)
    history: list[float] = []
    n_iter = 0
    for _ in range(config.max_iter + 1):
        logc = (ll_a + form.visual_loglik(ov, cond)).reshape(T, form.n_states, form.n_mix) + form.log_weights
        log_b = logsumexp(logc, axis=2)
        gamma, loglik, _, _ = forward_backward(form.log_startprob, form.log_transmat, log_b)
        history.append(loglik / T)
        if len(history) > 1 and history[-1] - history[-2] < config.tol:
            break
        if n_iter == config.max_iter:
            break
        ov = form.combine(_component_resp(gamma, logc, log_b), cond)
        n_iter += 1
    return HmmiResult(visual=ov, history=history, n_iter=n_iter)
