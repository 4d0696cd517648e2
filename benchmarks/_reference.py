"""A slow reference for the selection framework: the same model, fitted by public parts only.

:class:`ReferenceHMMGMR` is :class:`skhmmgmr.HMMGMRRegressor` with its EM engine replaced by
a plain implementation of the same algorithm that shares no numerics with the package's:
emission densities from ``sklearn.mixture`` (Cholesky factors, one pass over all rows per
state), hmmlearn's compiled scaled forward, backward and expected-transition kernels per
recording, moments by plain NumPy over all rows. The start is the package's algorithm
written again from public parts: k-means on the same evenly spaced sample of at most 100,000
rows (same offset, same random state), every row labelled by its nearest centre
(``sklearn.metrics.pairwise_distances_argmin``), the pooled covariance for a state with too
few rows, random transitions drawn next from the same random state. Everything else
(validation, standardisation, the causal GMR read-out, the selection logic) is the package's,
so that a difference between the two framework runs can only come from the numerics of the
fitted HMMs.
"""

import numpy as np
from hmmlearn import _hmmc
from sklearn.cluster import KMeans
from sklearn.metrics import pairwise_distances_argmin
from sklearn.mixture._gaussian_mixture import (
    _compute_precision_cholesky,
    _estimate_log_gaussian_prob,
)
from sklearn.utils import check_random_state

from skhmmgmr import HMMGMRRegressor
from skhmmgmr._hmm._em import EMResult, HMMParameters
from skhmmgmr._hmm._em_init import INIT_SAMPLE_ROWS
from skhmmgmr._hmm._emissions import MIN_STATE_WEIGHT, FullCovariance


def _gaussians(resp, X, reg_covar, previous=None, prior_scale=None):
    """Weighted Gaussians; the covariance gets ``reg_covar`` on its diagonal, or, given a
    ``prior_scale`` psi (the M-step), ``psi / weight``."""
    weights = resp.sum(axis=0)
    means = np.empty((resp.shape[1], X.shape[1]))
    covariances = np.empty((resp.shape[1], X.shape[1], X.shape[1]))
    for k, weight in enumerate(weights):
        if previous is not None and weight < MIN_STATE_WEIGHT:
            means[k], covariances[k] = previous.means[k], previous.covariances[k]
            continue
        means[k] = resp[:, k] @ X / weight
        diff = X - means[k]
        covariances[k] = (resp[:, k, np.newaxis] * diff).T @ diff / weight
        added = reg_covar if prior_scale is None else prior_scale / weight
        covariances[k].flat[:: X.shape[1] + 1] += added
    return weights, means, covariances


def _initial_parameters(X, n_states, reg_covar, random_state):
    sample = X
    if len(X) > INIT_SAMPLE_ROWS:
        step = -(-len(X) // INIT_SAMPLE_ROWS)
        sample = X[random_state.randint(step) :: step]
    kmeans = KMeans(n_clusters=n_states, n_init=1, random_state=random_state).fit(sample)
    labels = pairwise_distances_argmin(X, kmeans.cluster_centers_)
    resp = np.zeros((len(X), n_states))
    resp[np.arange(len(X)), labels] = 1.0
    weights, means, covariances = _gaussians(np.maximum(resp, 1e-300), X, reg_covar)
    pooled = np.cov(X, rowvar=False, bias=True) + reg_covar * np.eye(X.shape[1])
    covariances[weights < X.shape[1] + 1] = pooled
    means[weights < 1e-12] = X.mean(axis=0)
    startprob = np.full(n_states, 1.0 / n_states)
    transmat = random_state.dirichlet(np.ones(n_states), size=n_states)
    return HMMParameters.gaussian(startprob, transmat, means, covariances)


def _e_step(X, bounds, params):
    precisions_chol = _compute_precision_cholesky(params.covariances, "full")
    log_b = _estimate_log_gaussian_prob(X, params.means, precisions_chol, "full")
    top = log_b.max(axis=1, keepdims=True)
    frames = np.exp(log_b - top)
    resp = np.empty_like(frames)
    start = np.zeros(params.n_states)
    xi = np.zeros((params.n_states, params.n_states))
    log_likelihood = float(top.sum())
    for lo, hi in zip(bounds[:-1], bounds[1:], strict=True):
        rows = frames[lo:hi]
        log_p, fwd, scaling = _hmmc.forward_scaling(params.startprob, params.transmat, rows)
        bwd = _hmmc.backward_scaling(params.startprob, params.transmat, rows, scaling)
        log_likelihood += log_p
        posterior = fwd * bwd
        resp[lo:hi] = posterior / posterior.sum(axis=1, keepdims=True)
        start += resp[lo]
        if hi - lo > 1:
            xi += _hmmc.compute_scaling_xi_sum(fwd, params.transmat, bwd, rows)
    return log_likelihood, resp, start, xi


def reference_baum_welch(X, bounds, n_states, *, n_iter, tol, reg_covar, random_state):
    """EM from the package's k-means start; returns an :class:`skhmmgmr._hmm._em.EMResult`."""
    params = _initial_parameters(X, n_states, reg_covar, check_random_state(random_state))
    # The package's covariance prior: psi = reg_covar * n / K, penalty -psi/2 sum tr(S^-1).
    prior_scale = reg_covar * len(X) / n_states

    def objective(log_likelihood, params):
        inverse_traces = sum(np.trace(np.linalg.inv(cov)) for cov in params.covariances)
        return log_likelihood - 0.5 * prior_scale * inverse_traces

    history, objectives, converged = [], [], False
    for _ in range(n_iter):
        log_likelihood, resp, start, xi = _e_step(X, bounds, params)
        history.append(log_likelihood)
        objectives.append(objective(log_likelihood, params))
        if len(objectives) > 1 and abs(objectives[-1] - objectives[-2]) < tol * len(X):
            converged = True
            break
        transmat = xi / xi.sum(axis=1, keepdims=True)
        _, means, covariances = _gaussians(
            resp, X, reg_covar, previous=params, prior_scale=prior_scale
        )
        params = HMMParameters.gaussian(start / start.sum(), transmat, means, covariances)
    else:
        history.append(_e_step(X, bounds, params)[0])
        objectives.append(objective(history[-1], params))
    return EMResult(
        params,
        history[-1],
        history,
        min(len(history), n_iter),
        converged,
        objectives[-1],
        objectives,
    )


class ReferenceHMMGMR(HMMGMRRegressor):
    """:class:`~skhmmgmr.HMMGMRRegressor` fitted by :func:`reference_baum_welch`."""

    def _baum_welch(self, columns, recordings):
        bounds = np.append(recordings.starts, recordings.stops[-1])
        return reference_baum_welch(
            columns.rows(),
            bounds,
            self.n_states,
            n_iter=self.n_iter,
            tol=self.tol,
            reg_covar=self.reg_covar,
            random_state=self.random_state,
        )


class PeerHMMGMR(HMMGMRRegressor):
    """:class:`~skhmmgmr.HMMGMRRegressor` whose HMM is fitted by hmmlearn's ``GaussianHMM``.

    The peer library starts from the package's initial parameters (same k-means start, same
    random transitions), stops on the same per-row tolerance and uses the same covariance
    prior (hmmlearn's full-covariance M-step is ``(covars_prior + scatter) / N_k``), so that
    its time per model is comparable: its log-likelihood history equals ours (2.7e-13
    relative, measured). hmmlearn's monitor tracks the plain log-likelihood, not the penalised
    one, and takes a fall of it as convergence, so it may stop a few iterations earlier.
    """

    def _baum_welch(self, columns, recordings):
        from hmmlearn.hmm import GaussianHMM

        from skhmmgmr._hmm._em import initialize_parameters

        start = initialize_parameters(
            columns,
            recordings,
            self.n_states,
            self.init_params,
            self.reg_covar,
            check_random_state(self.random_state),
        )
        n_samples, n_dims = columns.n_samples, columns.n_features
        peer = GaussianHMM(
            n_components=self.n_states,
            covariance_type="full",
            n_iter=self.n_iter,
            tol=self.tol * n_samples,
            init_params="",
            covars_prior=FullCovariance.prior_for(self.reg_covar, n_samples, self.n_states).scale
            * np.eye(n_dims),
        )
        peer.startprob_, peer.transmat_ = start.startprob, start.transmat
        peer.means_, peer.covars_ = start.means, start.covariances
        peer.fit(columns.rows(), lengths=np.asarray(recordings.lengths))
        params = HMMParameters.gaussian(peer.startprob_, peer.transmat_, peer.means_, peer.covars_)
        history = list(peer.monitor_.history)
        return EMResult(params, history[-1], history, peer.monitor_.iter, peer.monitor_.converged)
