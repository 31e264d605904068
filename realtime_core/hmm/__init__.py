"""The audio-visual HMM: kernels, Gaussian-mixture model, Baum-Welch (paper Sec. 4.1).

kernels   log-space forward/backward, expected transitions, Viterbi
model     AvHmm (joint audio-visual Gaussian mixtures per state), component log-likelihoods
train     k-means initialisation, Baum-Welch with covariance priors (TrainConfig, fit)
sampling  random well-posed models and sequences (tests and benchmarks)
adapt     MAP speaker adaptation of the audio side (Gauvain & Lee 1994)
"""

from realtime_core.hmm.kernels import expected_transitions, forward_backward, log_backward, log_forward, viterbi
from realtime_core.hmm.model import AvHmm, component_loglik, gaussian_loglik
from realtime_core.hmm.train import TrainConfig, TrainResult, baum_welch, em_iteration, fit, init_model, log_likelihood

__all__ = [
    "AvHmm",
    "TrainConfig",
    "TrainResult",
    "baum_welch",
    "component_loglik",
    "em_iteration",
    "expected_transitions",
    "fit",
    "forward_backward",
    "gaussian_loglik",
    "init_model",
    "log_backward",
    "log_forward",
    "log_likelihood",
    "viterbi",
]
