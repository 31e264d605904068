"""Per-component audio-marginal and visual-conditional forms of the AV-HMM (eq. 5-7).

Theory of operation
-------------------
Partition each component's joint Cholesky factor ``L`` (``Sigma = L L^T``) as

    L = [[L_aa, 0   ],
         [L_va, L_vv]]

Then, with no matrix inverted:
  * the audio marginal is ``N(o_a; mu_a, L_aa L_aa^T)``: ``L_aa`` is already the Cholesky
    factor of ``Sigma_aa``;
  * the regression ``R = Sigma_va Sigma_aa^-1 = L_va L_aa^-1`` gives the Gaussian
    conditional mean ``m(o_a) = mu_v + R (o_a - mu_a)``;
  * the conditional covariance (Schur complement) is ``S = L_vv L_vv^T`` and the visual
    block of ``Sigma^-1`` is ``Phi_v = S^-1`` (eq. 6).

Eq. 7's bracket, ``Phi_v mu_v - 1/2 Phi_va (o_a - mu_a) - 1/2 [(o_a - mu_a)^T Phi_av]^T``,
equals ``Phi_v mu_v - Phi_va (o_a - mu_a)`` because ``Sigma^-1`` is symmetric, and since
``Phi_va = -Phi_v R`` it equals ``Phi_v m(o_a)``. So eq. 7 is the Phi_v-weighted average of
the per-component conditional means:

    o_v = [sum_c g_c Phi_v,c]^-1 sum_c g_c Phi_v,c m_c(o_a).

Everything that does not depend on the input is computed once here: the whitening
matrices ``W_c = L_aa,c^-1`` (4 x 4 and 77 x 77 triangular, from the factor), ``R_c``,
``Phi_v,c``, log-determinants, stacked into one matrix ``B`` so that a frame costs one
matrix-vector product ``B @ o_a`` plus O(N M) small work.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg

from realtime_core.errors import InvalidFeaturesError
from realtime_core.hmm.model import LOG_2PI, AvHmm


@dataclass(frozen=True, eq=False)
class ConditionalForm:
    """Precomputed per-component matrices (C = N M components, flattened j-major).

    B: ``(C * (Da + Dv), Da)`` stacked ``[W_c; R_c]``; offset: ``(C * (Da + Dv),)`` so that
    ``y = B @ o_a - offset`` holds ``W_c (o_a - mu_a,c)`` then ``m_c(o_a)`` per component.
    logdet_a: ``(C,)`` log|L_aa|; phi_v: ``(C, Dv, Dv)``; chol_vv: ``(C, Dv, Dv)``;
    logdet_v: ``(C,)`` log|L_vv|; log_weights: ``(N, M)``.
    """

    n_states: int
    n_mix: int
    n_audio: int
    n_visual: int
    B: np.ndarray
    offset: np.ndarray
    logdet_a: np.ndarray
    phi_v: np.ndarray
    chol_vv: np.ndarray
    logdet_v: np.ndarray
    log_weights: np.ndarray
    log_startprob: np.ndarray
    log_transmat: np.ndarray

    @classmethod
    def from_model(cls, model: AvHmm) -> ConditionalForm:
        n, m, d = model.means.shape
        da, dv = model.n_audio, model.n_visual
        c = n * m
        L = model.chol.reshape(c, d, d)
        mu = model.means.reshape(c, d)
        B = np.empty((c, da + dv, da))
        offset = np.empty((c, da + dv))
        phi_v = np.empty((c, dv, dv))
        eye = np.eye(da)
        for i in range(c):
            laa, lva, lvv = L[i, :da, :da], L[i, da:, :da], L[i, da:, da:]
            W = scipy.linalg.solve_triangular(laa, eye, lower=True, check_finite=False)
            R = lva @ W
            B[i, :da] = W
            B[i, da:] = R
            offset[i, :da] = W @ mu[i, :da]
            offset[i, da:] = R @ mu[i, :da] - mu[i, da:]
            lvv_inv = scipy.linalg.solve_triangular(lvv, np.eye(dv), lower=True, check_finite=False)
            phi_v[i] = lvv_inv.T @ lvv_inv
        diag = np.diagonal(L, axis1=1, axis2=2)
        return cls(
            n_states=n,
            n_mix=m,
            n_audio=da,
            n_visual=dv,
            B=B.reshape(c * (da + dv), da),
            offset=offset.reshape(-1),
            logdet_a=np.log(diag[:, :da]).sum(axis=1),
            phi_v=phi_v,
            chol_vv=L[:, da:, da:].copy(),
            logdet_v=np.log(diag[:, da:]).sum(axis=1),
            log_weights=model.log_weights,
            log_startprob=model.log_startprob,
            log_transmat=model.log_transmat,
        )

    @property
    def n_components(self) -> int:
        return self.n_states * self.n_mix

    def audio_terms(self, oa: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """For frames ``oa (T, Da)``: ``(log N(o_a; mu_a, Sigma_aa) (T, C), m_c(o_a) (T, C, Dv))``."""
        if oa.ndim != 2 or oa.shape[1] != self.n_audio:
            raise InvalidFeaturesError(f"audio features must be (T, {self.n_audio}), got {oa.shape}")
        if not np.all(np.isfinite(oa)):
            raise InvalidFeaturesError("audio features contain NaN or inf")
        y = (oa @ self.B.T - self.offset).reshape(len(oa), self.n_components, self.n_audio + self.n_visual)
        z = y[:, :, : self.n_audio]
        ll = -0.5 * np.einsum("tci,tci->tc", z, z) - self.logdet_a - 0.5 * self.n_audio * LOG_2PI
        return ll, y[:, :, self.n_audio :]

    def visual_loglik(self, ov: np.ndarray, cond_mean: np.ndarray) -> np.ndarray:
        """``log N(o_v; m_c, S_c)`` for ``ov (T, Dv)``, ``cond_mean (T, C, Dv)`` -> ``(T, C)``."""
        diff = ov[:, None, :] - cond_mean  # (T, C, Dv)
        # Solve L_vv z = diff for all (t, c): small Dv, batched.
        z = np.linalg.solve(self.chol_vv[None], diff[..., None])[..., 0]
        return -0.5 * np.einsum("tci,tci->tc", z, z) - self.logdet_v - 0.5 * self.n_visual * LOG_2PI

    def combine(self, resp: np.ndarray, cond_mean: np.ndarray) -> np.ndarray:
        """Eq. 7: ``resp (T, C)`` posteriors, ``cond_mean (T, C, Dv)`` -> ``o_v (T, Dv)``."""
        P = np.einsum("tc,cij->tij", resp, self.phi_v)  # (T, Dv, Dv)
        rhs = np.einsum("tc,cij,tcj->ti", resp, self.phi_v, cond_mean)
        return np.linalg.solve(P, rhs[..., None])[..., 0]
