"""Baum-Welch (EM) engine for a full-covariance Gaussian HMM over several recordings.

The template follows ``sklearn.mixture``: initialise, E-step, M-step, log-likelihood,
convergence test, ``n_init`` restarts keeping the best log-likelihood. The forward-backward
recursions run per recording in hmmlearn's compiled kernels (scaled form); the emission
densities and the sufficient statistics are computed for all rows at once with BLAS products.

The estimator talks to this module only through :func:`fit_hmm`, :func:`score_hmm` and
:class:`HMMParameters`.
"""

from dataclasses import dataclass, field, replace

import numpy as np
from hmmlearn import _hmmc
from sklearn.cluster import KMeans, kmeans_plusplus
from sklearn.utils import check_random_state

from ._gaussian import (
    NotPositiveDefiniteError,
    compute_precision_cholesky,
    estimate_gaussian_covariances_full,
    estimate_log_gaussian_prob,
)

INIT_METHODS = ("kmeans", "k-means++", "random", "random_from_data")

# A state whose expected number of rows falls below this keeps its previous emission
# parameters: less than one row of posterior mass cannot define a Gaussian, and freezing the
# state (instead of re-seeding it) keeps the log-likelihood non-decreasing.
MIN_STATE_WEIGHT = 1.0


@dataclass
class HMMParameters:
    """Parameters of a Gaussian HMM (in the engine's working units)."""

    startprob: np.ndarray
    transmat: np.ndarray
    means: np.ndarray
    covariances: np.ndarray
    precisions_chol: np.ndarray = field(default=None)

    def __post_init__(self):
        if self.precisions_chol is None:
            self.precisions_chol = compute_precision_cholesky(self.covariances)

    @property
    def n_states(self):
        return self.means.shape[0]


@dataclass
class EMResult:
    parameters: HMMParameters
    log_likelihood: float
    history: list
    n_iter: int
    converged: bool


@dataclass
class _Statistics:
    log_likelihood: float
    resp: np.ndarray
    start_counts: np.ndarray
    transition_counts: np.ndarray


def _frame_probabilities(X, params):
    """Emission likelihoods scaled per row (max 1), and the per-row log scale."""
    log_prob = estimate_log_gaussian_prob(X, params.means, params.precisions_chol)
    row_max = log_prob.max(axis=1, keepdims=True)
    log_prob -= row_max
    np.exp(log_prob, out=log_prob)
    return log_prob, row_max[:, 0]


def e_step(X, recordings, params):
    """Forward-backward over every recording: posteriors and expected transition counts."""
    frameprob, log_scale = _frame_probabilities(X, params)
    n_states = params.n_states
    resp = np.empty_like(frameprob)
    start_counts = np.zeros(n_states)
    transition_counts = np.zeros((n_states, n_states))
    log_likelihood = float(log_scale.sum())
    for _, rows in recordings.slices():
        frames = frameprob[rows]
        try:
            log_prob, fwd, scaling = _hmmc.forward_scaling(
                params.startprob, params.transmat, frames
            )
        except ValueError as exc:
            raise FloatingPointError(
                "the forward pass underflowed: a recording is impossible under the current "
                "transition matrix"
            ) from exc
        bwd = _hmmc.backward_scaling(params.startprob, params.transmat, frames, scaling)
        post = fwd * bwd
        post /= post.sum(axis=1, keepdims=True)
        resp[rows] = post
        start_counts += post[0]
        if frames.shape[0] > 1:
            transition_counts += _hmmc.compute_scaling_xi_sum(fwd, params.transmat, bwd, frames)
        log_likelihood += log_prob
    return _Statistics(log_likelihood, resp, start_counts, transition_counts)


def score_hmm(X, recordings, params):
    """Log-likelihood of all recordings (forward pass only)."""
    frameprob, log_scale = _frame_probabilities(X, params)
    log_likelihood = float(log_scale.sum())
    for _, rows in recordings.slices():
        log_prob, _, _ = _hmmc.forward_scaling(params.startprob, params.transmat, frameprob[rows])
        log_likelihood += log_prob
    return log_likelihood


def m_step(X, stats, previous, reg_covar):
    """Maximisation step; every covariance gets ``reg_covar`` on its diagonal."""
    startprob = stats.start_counts / stats.start_counts.sum()
    row_sums = stats.transition_counts.sum(axis=1, keepdims=True)
    transmat = np.where(
        row_sums > 0,
        stats.transition_counts / np.where(row_sums > 0, row_sums, 1.0),
        previous.transmat,
    )
    state_weights = stats.resp.sum(axis=0)
    alive = state_weights >= MIN_STATE_WEIGHT
    safe_weights = np.where(alive, state_weights, 1.0)
    means = (stats.resp.T @ X) / safe_weights[:, np.newaxis]
    covariances = estimate_gaussian_covariances_full(stats.resp, X, safe_weights, means, reg_covar)
    means[~alive] = previous.means[~alive]
    covariances[~alive] = previous.covariances[~alive]
    return HMMParameters(startprob, transmat, means, covariances)


def initialize_parameters(X, recordings, n_states, init_params, reg_covar, random_state):
    """Initial parameters: emissions from a hard clustering, random transitions."""
    n_samples, n_features = X.shape
    if init_params == "kmeans":
        labels = KMeans(n_clusters=n_states, n_init=1, random_state=random_state).fit(X).labels_
        resp = np.zeros((n_samples, n_states))
        resp[np.arange(n_samples), labels] = 1.0
    elif init_params == "random":
        resp = random_state.uniform(size=(n_samples, n_states))
        resp /= resp.sum(axis=1, keepdims=True)
    else:
        if init_params == "k-means++":
            centers, _ = kmeans_plusplus(X, n_states, random_state=random_state)
        else:
            centers = X[random_state.choice(n_samples, size=n_states, replace=False)]
        distances = ((X[:, np.newaxis, :] - centers[np.newaxis]) ** 2).sum(axis=2)
        resp = np.zeros((n_samples, n_states))
        resp[np.arange(n_samples), distances.argmin(axis=1)] = 1.0
    state_weights = resp.sum(axis=0)
    means = (resp.T @ X) / np.maximum(state_weights, 1e-12)[:, np.newaxis]
    covariances = estimate_gaussian_covariances_full(
        resp, X, np.maximum(state_weights, 1e-12), means, reg_covar
    )
    # A cluster with fewer rows than dimensions has a singular scatter: give it the pooled
    # covariance instead, so that EM starts from usable Gaussians.
    small = state_weights < n_features + 1
    if np.any(small):
        pooled = np.cov(X, rowvar=False).reshape(n_features, n_features)
        pooled.flat[:: n_features + 1] += reg_covar
        covariances[small] = pooled
        means[small & (state_weights < 1e-12)] = X.mean(axis=0)
    startprob = np.full(n_states, 1.0 / n_states)
    transmat = random_state.dirichlet(np.ones(n_states), size=n_states)
    return HMMParameters(startprob, transmat, means, covariances)


def baum_welch(X, recordings, params, *, n_iter, tol, reg_covar, callback=None):
    """Run EM from ``params`` until the per-row log-likelihood gain is below ``tol``.

    ``history`` holds the log-likelihood of the parameters in force before each M-step and,
    last, that of the returned parameters.
    """
    n_samples = X.shape[0]
    history = []
    converged = False
    n_done = 0
    for n_done in range(1, n_iter + 1):
        stats = e_step(X, recordings, params)
        history.append(stats.log_likelihood)
        if callback is not None:
            callback(n_done, stats.log_likelihood)
        if len(history) > 1 and abs(history[-1] - history[-2]) < tol * n_samples:
            converged = True
            break
        params = m_step(X, stats, params, reg_covar)
    else:
        history.append(score_hmm(X, recordings, params))
    return EMResult(params, history[-1], history, n_done, converged)


def fit_hmm(
    X,
    recordings,
    n_states,
    *,
    n_init=1,
    init_params="kmeans",
    n_iter=100,
    tol=1e-4,
    reg_covar=1e-6,
    random_state=None,
    initial_parameters=None,
):
    """Fit a Gaussian HMM with ``n_init`` restarts and return the best :class:`EMResult`.

    When ``converged`` is reached the last E-step already scored the returned parameters
    (they were not updated after it); otherwise the returned parameters are scored once more.
    """
    random_state = check_random_state(random_state)
    best = None
    for _ in range(n_init):
        if initial_parameters is not None:
            params = replace(initial_parameters)
        else:
            params = initialize_parameters(
                X, recordings, n_states, init_params, reg_covar, random_state
            )
        try:
            result = baum_welch(X, recordings, params, n_iter=n_iter, tol=tol, reg_covar=reg_covar)
        except NotPositiveDefiniteError as exc:
            raise ValueError(
                f"EM failed: {exc}. The data are probably collinear or a state collapsed on "
                f"a few rows (reg_covar={reg_covar})."
            ) from exc
        if best is None or result.log_likelihood > best.log_likelihood:
            best = result
    return best
