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

Everything that does not depend on the input is computed once here. The audio
quadratic form ``(o_a - mu_a)^T Sigma_aa^-1 (o_a - mu_a)`` is expanded around a global
centre ``g`` (``a = o_a - g``) as ``q_c . [a_i a_j (i <= j); a] + const_c``: the products
``a_i a_j`` are formed once per frame and shared by every component, so the likelihoods of
all C components cost one ``(C, Da (Da + 1) / 2 + Da)`` matrix-vector product, half of what
whitening each component (``L_aa^-1 a``) would cost and with no per-component work. The
conditional means need a second, ``(C Dv, Da)`` product. ``Sigma_aa^-1 = W^T W`` with
``W = L_aa^-1`` from a triangular solve.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg

from realtime_core.errors import InvalidFeaturesError
from realtime_core.hmm.model import LOG_2PI, AvHmm, quadratic_coefficients, quadratic_features


@dataclass(frozen=True, eq=False)
class ConditionalForm:
    """Precomputed per-component matrices (C = N M components, flattened j-major).

    center: ``(Da,)`` g; quad: ``(C, K)`` with ``K = Da (Da + 1) / 2 + Da``; quad0: ``(C,)``
    so that ``log N(o_a; mu_a, Sigma_aa) = -0.5 (quad @ [a_i a_j; a] + quad0)``;
    reg: ``(C * Dv, Da)`` and reg0: ``(C * Dv,)`` so that ``m_c(o_a) = reg @ a + reg0``;
    phi_v: ``(C, Dv, Dv)``; chol_vv: ``(C, Dv, Dv)``; logdet_v: ``(C,)`` log|L_vv|;
    log_weights: ``(N, M)``; log_startprob: ``(N,)``; log_transmat: ``(N, N)``.
    """

    n_states: int
    n_mix: int
    n_audio: int
    n_visual: int
    center: np.ndarray
    quad: np.ndarray
    quad0: np.ndarray
    reg: np.ndarray
    reg0: np.ndarray
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
        center = (model.weights.reshape(c, 1) * mu[:, :da]).sum(axis=0) / n
        # The audio marginal's factor is the leading block of the joint one.
        quad, quad0 = quadratic_coefficients(mu[:, :da] - center, L[:, :da, :da])
        reg = np.empty((c, dv, da))
        reg0 = np.empty((c, dv))
        phi_v = np.empty((c, dv, dv))
        eye_a, eye_v = np.eye(da), np.eye(dv)
        for i in range(c):
            laa, lva, lvv = L[i, :da, :da], L[i, da:, :da], L[i, da:, da:]
            W = scipy.linalg.solve_triangular(laa, eye_a, lower=True, check_finite=False)
            R = lva @ W  # Sigma_va Sigma_aa^-1
            reg[i] = R
            reg0[i] = mu[i, da:] - R @ (mu[i, :da] - center)
            lvv_inv = scipy.linalg.solve_triangular(lvv, eye_v, lower=True, check_finite=False)
            phi_v[i] = lvv_inv.T @ lvv_inv
        return cls(
            n_states=n,
            n_mix=m,
            n_audio=da,
            n_visual=dv,
            center=center,
            quad=quad,
            quad0=quad0,
            reg=reg.reshape(c * dv, da),
            reg0=reg0.reshape(-1),
            phi_v=phi_v,
            chol_vv=L[:, da:, da:].copy(),
            logdet_v=np.log(np.diagonal(L[:, da:, da:], axis1=1, axis2=2)).sum(axis=1),
            log_weights=model.log_weights,
            log_startprob=model.log_startprob,
            log_transmat=model.log_transmat,
        )

    @property
    def n_components(self) -> int:
        return self.n_states * self.n_mix

    def quad_features(self, oa: np.ndarray) -> np.ndarray:
        """``oa (T, Da) -> (T, K)``: ``[a_i a_j (i <= j); a]`` with ``a = o_a - center``."""
        return quadratic_features(oa - self.center)

    def audio_terms(self, oa: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """For frames ``oa (T, Da)``: ``(log N(o_a; mu_a, Sigma_aa) (T, C), m_c(o_a) (T, C, Dv))``."""
        if oa.ndim != 2 or oa.shape[1] != self.n_audio:
            raise InvalidFeaturesError(f"audio features must be (T, {self.n_audio}), got {oa.shape}")
        if not np.all(np.isfinite(oa)):
            raise InvalidFeaturesError("audio features contain NaN or inf")
        ll = -0.5 * (self.quad_features(oa) @ self.quad.T + self.quad0)
        cond = ((oa - self.center) @ self.reg.T + self.reg0).reshape(len(oa), self.n_components, self.n_visual)
        return ll, cond

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
