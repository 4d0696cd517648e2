"""Pure numerical functions on full-covariance Gaussians.

Every function works on Cholesky factors of the precision matrices, as
``sklearn.mixture`` does: for a covariance ``S = L L^T`` (``L`` lower triangular) the precision
Cholesky factor is ``P = L^{-T}`` (upper triangular), so that ``S^{-1} = P P^T`` and the Mahalanobis
distance of ``x`` is ``||(x - mu) @ P||^2``. One matrix product per state gives the log-densities
of all rows.
"""

import numpy as np
from scipy import linalg

LOG_2PI = np.log(2.0 * np.pi)


class NotPositiveDefiniteError(ValueError):
    """A state covariance is not positive definite even after regularisation."""


def estimate_gaussian_covariances_full(resp, X, state_weights, means, reg_covar):
    """Weighted covariance of every state, with ``reg_covar`` added to its diagonal.

    Parameters
    ----------
    resp : ndarray of shape (n_samples, n_states)
        State posteriors (responsibilities) of every row.
    X : ndarray of shape (n_samples, n_features)
    state_weights : ndarray of shape (n_states,)
        Column sums of ``resp`` (expected number of rows per state), strictly positive.
    means : ndarray of shape (n_states, n_features)
    reg_covar : float
        Non-negative value added to every diagonal element.

    Returns
    -------
    covariances : ndarray of shape (n_states, n_features, n_features)
    """
    n_states, n_features = means.shape
    covariances = np.empty((n_states, n_features, n_features))
    for k in range(n_states):
        diff = X - means[k]
        weighted = diff * resp[:, k, np.newaxis]
        covariances[k] = (weighted.T @ diff) / state_weights[k]
        covariances[k] = 0.5 * (covariances[k] + covariances[k].T)
        covariances[k].flat[:: n_features + 1] += reg_covar
    return covariances


def compute_precision_cholesky(covariances):
    """Cholesky factors of the precision matrices of full covariances.

    Raises
    ------
    NotPositiveDefiniteError
        Naming the state whose covariance cannot be factorised.
    """
    n_states, n_features, _ = covariances.shape
    precisions_chol = np.empty_like(covariances)
    for k, covariance in enumerate(covariances):
        try:
            cov_chol = linalg.cholesky(covariance, lower=True)
        except linalg.LinAlgError as exc:
            raise NotPositiveDefiniteError(
                f"the covariance of state {k} is not positive definite; increase reg_covar "
                "or reduce n_states"
            ) from exc
        precisions_chol[k] = linalg.solve_triangular(cov_chol, np.eye(n_features), lower=True).T
    return precisions_chol


def covariances_from_precision_cholesky(precisions_chol):
    """Inverse of :func:`compute_precision_cholesky`."""
    covariances = np.empty_like(precisions_chol)
    eye = np.eye(precisions_chol.shape[1])
    for k, prec_chol in enumerate(precisions_chol):
        inv = linalg.solve_triangular(prec_chol, eye, lower=False)
        covariances[k] = inv @ inv.T
    return covariances


def log_det_cholesky(precisions_chol):
    """``log det(P)`` of every precision Cholesky factor, i.e. ``-0.5 log det(S)``."""
    diagonals = np.diagonal(precisions_chol, axis1=1, axis2=2)
    return np.sum(np.log(diagonals), axis=1)


def estimate_log_gaussian_prob(X, means, precisions_chol):
    """Log-density of every row under every state's Gaussian.

    Returns
    -------
    log_prob : ndarray of shape (n_samples, n_states)
    """
    n_samples, n_features = X.shape
    n_states = means.shape[0]
    log_det = log_det_cholesky(precisions_chol)
    log_prob = np.empty((n_samples, n_states))
    for k in range(n_states):
        # (X - mu) P computed as X P - mu P: one BLAS product on the raw rows, no centred copy.
        y = X @ precisions_chol[k]
        y -= means[k] @ precisions_chol[k]
        np.einsum("ij,ij->i", y, y, out=log_prob[:, k])
    log_prob *= -0.5
    log_prob += log_det - 0.5 * n_features * LOG_2PI
    return log_prob
