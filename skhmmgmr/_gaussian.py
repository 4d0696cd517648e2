"""Pure numerical functions on full-covariance Gaussians.

Every function works on Cholesky factors of the precision matrices, as
``sklearn.mixture`` does: for a covariance ``S = L L^T`` (``L`` lower triangular) the precision
Cholesky factor is ``P = L^{-T}`` (upper triangular), so that ``S^{-1} = P P^T`` and the Mahalanobis
distance of ``x`` is ``||(x - mu) @ P||^2``. One matrix product per state gives the log-densities
of all rows.

For long arrays the products are done in chunks of rows (:data:`CHUNK_SIZE`), with the
factors of all states stacked side by side: one product per chunk instead of one pass over all
rows per state keeps the work in cache. The weighted moments of the M-step are accumulated in
the same chunks, about a fixed shift point, without per-state centred copies of the data.
"""

import numpy as np
from scipy import linalg

LOG_2PI = np.log(2.0 * np.pi)

# Rows per chunk: a chunk's stacked products (rows x states x features doubles) should stay
# within a few megabytes so that the chunk is still in cache when it is reduced.
CHUNK_SIZE = 8192


class NotPositiveDefiniteError(ValueError):
    """A state covariance is not positive definite even after regularisation."""


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


def log_det_cholesky(precisions_chol):
    """``log det(P)`` of every precision Cholesky factor, i.e. ``-0.5 log det(S)``."""
    diagonals = np.diagonal(precisions_chol, axis1=1, axis2=2)
    return np.sum(np.log(diagonals), axis=1)


def chunk_size_for(n_columns, chunk_size=None):
    """Rows per chunk so that a ``(n_columns, rows)`` temporary stays within about 4 MB."""
    if chunk_size is not None:
        return max(int(chunk_size), 1)
    return int(np.clip((1 << 19) // max(n_columns, 1), 1024, CHUNK_SIZE))


def stack_gaussians(means, precisions_chol, shift=None):
    """Stacked precision factors for :func:`log_gaussian_prob_stacked`.

    Parameters
    ----------
    means : ndarray of shape (n_states, n_features)
    precisions_chol : ndarray of shape (n_states, n_features, n_features)
    shift : ndarray of shape (n_features,), default=None
        Point subtracted from the rows before the product (zero when None).

    Returns
    -------
    factors : ndarray of shape (n_states * n_features, n_features)
        ``[P_0^T; P_1^T; ...]`` stacked vertically.
    offsets : ndarray of shape (n_states * n_features, 1)
        ``[(mu_0 - shift) P_0, ...]`` as a column.
    norms : ndarray of shape (n_states, 1)
        Log normalising constants ``log det(P_k) - n_features / 2 log(2 pi)``.
    """
    n_states, n_features = means.shape
    centred = means if shift is None else means - shift
    factors = np.ascontiguousarray(precisions_chol.transpose(0, 2, 1)).reshape(
        n_states * n_features, n_features
    )
    offsets = np.einsum("kf,kfg->kg", centred, precisions_chol).reshape(-1, 1)
    norms = log_det_cholesky(precisions_chol) - 0.5 * n_features * LOG_2PI
    return factors, offsets, norms[:, np.newaxis]


def shifted_transpose(X, shift=None):
    """``(X - shift).T`` as a C-contiguous (n_features, n_rows) array."""
    out = np.empty((X.shape[1], X.shape[0]))
    if shift is None:
        out[...] = X.T
        return out
    return np.subtract(X.T, shift[:, np.newaxis], out=out)


def log_gaussian_prob_stacked(XT, factors, offsets, norms):
    """Log-densities of the rows of one chunk, state-major (see :func:`stack_gaussians`).

    The chunk is given transposed, ``XT`` of shape (n_features, n_rows), with the ``shift`` of
    :func:`stack_gaussians` already subtracted (see :func:`shifted_transpose`). The result has
    shape (n_states, n_rows): every elementwise step and every reduction over states then runs
    along long contiguous rows, which NumPy vectorises, instead of along a short last axis.
    """
    n_states = norms.shape[0]
    projected = factors @ XT
    projected -= offsets
    np.square(projected, out=projected)
    log_prob = projected.reshape(n_states, -1, XT.shape[1]).sum(axis=1)
    log_prob *= -0.5
    log_prob += norms
    return log_prob


def estimate_log_gaussian_prob(X, means, precisions_chol, chunk_size=None):
    """Log-density of every row under every state's Gaussian.

    Parameters
    ----------
    X : ndarray of shape (n_samples, n_features)
    means : ndarray of shape (n_states, n_features)
    precisions_chol : ndarray of shape (n_states, n_features, n_features)
    chunk_size : int, default=None
        Rows per chunk; the default keeps the temporaries of a chunk in cache.

    Returns
    -------
    log_prob : ndarray of shape (n_samples, n_states)
    """
    n_samples = X.shape[0]
    n_states, n_features = means.shape
    stacked = stack_gaussians(means, precisions_chol)
    log_prob = np.empty((n_samples, n_states))
    step = chunk_size_for(n_states * n_features, chunk_size)
    for start in range(0, n_samples, step):
        rows = slice(start, start + step)
        log_prob[rows] = log_gaussian_prob_stacked(shifted_transpose(X[rows]), *stacked).T
    return log_prob


def accumulate_moments(respT, XT, first, second):
    """Add the weighted first and second raw moments of one chunk to ``first`` and ``second``.

    Parameters
    ----------
    respT : ndarray of shape (n_states, n_rows)
        Posteriors of the chunk, state-major.
    XT : ndarray of shape (n_features, n_rows)
        Rows of the chunk, shifted and transposed (see :func:`shifted_transpose`).
    first : ndarray of shape (n_states, n_features)
        ``sum_t r_tk x_t``, updated in place.
    second : ndarray of shape (n_states, n_features, n_features)
        ``sum_t r_tk x_t x_t^T``, updated in place.
    """
    n_features, n_rows = XT.shape
    n_states = respT.shape[0]
    first += respT @ XT.T
    # All states' weighted rows in one (n_states * n_features, n_rows) array: one product.
    weighted = (respT[:, np.newaxis, :] * XT[np.newaxis]).reshape(-1, n_rows)
    second += (weighted @ XT.T).reshape(n_states, n_features, n_features)


def weighted_moments(resp, X, shift=None, chunk_size=None):
    """State weights and weighted raw moments about ``shift``, accumulated chunk by chunk.

    Parameters
    ----------
    resp : ndarray of shape (n_samples, n_states)
    X : ndarray of shape (n_samples, n_features)
    shift : ndarray of shape (n_features,), default=None
    chunk_size : int, default=None

    Returns
    -------
    weights : ndarray of shape (n_states,)
    first : ndarray of shape (n_states, n_features)
        ``sum_t r_tk (x_t - shift)``.
    second : ndarray of shape (n_states, n_features, n_features)
        ``sum_t r_tk (x_t - shift) (x_t - shift)^T``.
    """
    n_samples, n_features = X.shape
    n_states = resp.shape[1]
    weights = resp.sum(axis=0)
    first = np.zeros((n_states, n_features))
    second = np.zeros((n_states, n_features, n_features))
    step = chunk_size_for(n_states * n_features, chunk_size)
    for start in range(0, n_samples, step):
        rows = slice(start, start + step)
        respT = np.ascontiguousarray(resp[rows].T)
        accumulate_moments(respT, shifted_transpose(X[rows], shift), first, second)
    return weights, first, second


def gaussians_from_moments(weights, first, second, reg_covar, shift=None):
    """Means and covariances (with ``reg_covar`` on the diagonal) from raw moments.

    ``weights`` must be strictly positive. The covariance is ``E[x x^T] - E[x] E[x]^T`` about
    the shift point; with the shift near the data (the engine uses the data mean, and the
    estimator standardises the data) the subtraction loses no significant digits.
    """
    n_features = first.shape[1]
    centred_means = first / weights[:, np.newaxis]
    covariances = second / weights[:, np.newaxis, np.newaxis]
    covariances -= centred_means[:, :, np.newaxis] * centred_means[:, np.newaxis, :]
    covariances += covariances.transpose(0, 2, 1)
    covariances *= 0.5
    covariances.reshape(covariances.shape[0], -1)[:, :: n_features + 1] += reg_covar
    means = centred_means if shift is None else centred_means + shift
    return means, covariances
