"""Pure numerical functions on full-covariance Gaussians.

Every function works on Cholesky factors of the precision matrices, as
``sklearn.mixture`` does: for a covariance ``S = L L^T`` (``L`` lower triangular) the precision
Cholesky factor is ``P = L^{-T}`` (upper triangular), so that ``S^{-1} = P P^T`` and the Mahalanobis
distance of ``x`` is ``||(x - mu) @ P||^2``.

The data are handled as *augmented columns*: the rows of ``X - shift`` as the columns of a
C-contiguous ``(n_features + 1, n_rows)`` array whose last row is ones. One product of the
stacked factors of all states (offsets in the last column) with a chunk of columns gives the
Mahalanobis terms of every state; one product of the posteriors of all states with the
pairwise products of the columns (or, for a lone state, one symmetric product) gives the
weights, first and second moments about the shift point. Chunks of :data:`CHUNK_SIZE` rows
keep each product's output in cache while it is reduced.
"""

import threading
from contextlib import contextmanager

import numpy as np
from scipy import linalg
from threadpoolctl import ThreadpoolController

from ._kernels import pairwise_products, weighted_pair_sums

LOG_2PI = np.log(2.0 * np.pi)

# Rows per chunk: a chunk's stacked products (rows x states x features doubles) should stay
# within a few megabytes so that the chunk is still in cache when it is reduced.
CHUNK_SIZE = 8192


_CONTROLLER = []
_NESTING = threading.local()


@contextmanager
def one_blas_thread():
    """Context in which every loaded BLAS runs on one thread.

    The engine's BLAS calls are small (a few states by a few columns, or one chunk of rows):
    OpenBLAS threads them on two cores at a loss, and a threaded triangular solve of a 3x3
    system takes 7-11 ms instead of 20 us (measured, OpenBLAS 0.3.31 on 2 cores), once per
    state and M-step. The controller is built at first use, when NumPy's and SciPy's BLAS are
    both loaded. Setting the limit costs tens of microseconds (threadpoolctl asks every
    library), as much as a factorisation of the states' covariances: a context entered inside
    another (of the same thread) keeps the limit already set and costs nothing.
    """
    if getattr(_NESTING, "depth", 0):
        _NESTING.depth += 1
        try:
            yield
        finally:
            _NESTING.depth -= 1
        return
    if not _CONTROLLER:
        _CONTROLLER.append(ThreadpoolController())
    with _CONTROLLER[0].limit(limits=1, user_api="blas"):
        _NESTING.depth = 1
        try:
            yield
        finally:
            _NESTING.depth = 0


class NotPositiveDefiniteError(ValueError):
    """A state covariance is not positive definite even after regularisation."""


def compute_precision_cholesky(covariances):
    """Cholesky factors of the precision matrices of full covariances.

    LAPACK's ``potrf`` and ``trtrs`` are called directly, state by state: the same routines on
    the same arrays as ``scipy.linalg.cholesky`` and ``solve_triangular`` (the factors are
    bit-identical), without their checks and conversions, which cost ten times the
    factorisation of a state's 6x6 covariance.

    Raises
    ------
    NotPositiveDefiniteError
        Naming the state whose covariance cannot be factorised.
    ValueError
        If a covariance holds NaN or infinity.
    """
    covariances = np.asarray(covariances)
    n_states, n_features, _ = covariances.shape
    finite = np.isfinite(covariances).all(axis=(1, 2))
    if not finite.all():
        raise ValueError(
            f"the covariance of state {np.flatnonzero(~finite)[0]} holds NaN or infinity"
        )
    potrf, trtrs = linalg.get_lapack_funcs(("potrf", "trtrs"), (covariances,))
    identity = np.eye(n_features, dtype=covariances.dtype)
    precisions_chol = np.empty_like(covariances)
    with one_blas_thread():
        for k, covariance in enumerate(covariances):
            cov_chol, info = potrf(covariance, lower=True, clean=True)
            if info == 0:
                solved, info = trtrs(cov_chol, identity, lower=True)
            if info != 0:
                raise NotPositiveDefiniteError(
                    f"the covariance of state {k} is not positive definite; increase "
                    "reg_covar or reduce n_states"
                )
            precisions_chol[k] = solved.T
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
        Point subtracted from the rows of the columns (see :func:`augmented_columns`).

    Returns
    -------
    factors : ndarray of shape (n_states * n_features, n_features + 1)
        ``[P_k^T, -P_k^T (mu_k - shift)] / sqrt(2)`` stacked vertically: one product with the
        augmented columns gives every state's scaled Mahalanobis terms, offset included.
    norms : ndarray of shape (n_states, 1)
        Log normalising constants ``log det(P_k) - n_features / 2 log(2 pi)``.
    """
    n_states, n_features = means.shape
    centred = means if shift is None else means - shift
    factors = np.empty((n_states, n_features, n_features + 1))
    factors[:, :, :n_features] = precisions_chol.transpose(0, 2, 1)
    factors[:, :, n_features] = -np.einsum("kf,kfg->kg", centred, precisions_chol)
    factors *= np.sqrt(0.5)
    norms = log_det_cholesky(precisions_chol) - 0.5 * n_features * LOG_2PI
    return factors.reshape(n_states * n_features, n_features + 1), norms[:, np.newaxis]


def augmented_columns(X, shift=None):
    """The rows of ``X - shift`` as columns, with a last row of ones.

    Returns a C-contiguous array of shape (n_features + 1, n_rows): a chunk of rows is then a
    slice of columns that every product reads as it is, and the row of ones carries the
    offsets of :func:`stack_gaussians` and the weights and first moments of
    :class:`MomentSums`.
    """
    n_rows, n_features = X.shape
    out = np.empty((n_features + 1, n_rows))
    if shift is None:
        out[:n_features] = X.T
    else:
        np.subtract(X.T, shift[:, np.newaxis], out=out[:n_features])
    out[n_features] = 1.0
    return out


def log_gaussian_prob_stacked(columns, factors, norms):
    """Log-densities of the rows of one chunk under every state, shape (n_states, n_rows).

    ``columns`` are augmented columns (:func:`augmented_columns`) shifted as the ``shift`` of
    :func:`stack_gaussians`. The result is state-major: every elementwise step and every
    reduction over states then runs along long contiguous rows, which NumPy vectorises.
    """
    n_states = norms.shape[0]
    projected = factors @ columns
    np.square(projected, out=projected)
    half_distances = projected.reshape(n_states, -1, columns.shape[1]).sum(axis=1)
    return np.subtract(norms, half_distances, out=half_distances)


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
        log_prob[rows] = log_gaussian_prob_stacked(augmented_columns(X[rows]), *stacked).T
    return log_prob


# The pairwise products of one sub-chunk of rows take at most this many values (512 KB), so
# that they are still in the core's cache when the product with the posteriors reads them.
PAIR_BUFFER_VALUES = 1 << 16


class MomentSums:
    """Weighted moments ``sum_t r_tk [x_t; 1] [x_t; 1]^T`` of augmented columns, chunk by chunk.

    The result holds, per state, the second moments, the first moments in the last column and
    the weight in the corner (see :func:`split_moments`). Two ways give the same sums (to
    round-off):

    - ``"pairs"``: one product of all states' posteriors with the pairwise products of the
      columns (``x_a x_b`` for ``a <= b``), built for sub-chunks of rows small enough to stay
      in cache: one BLAS call per sub-chunk instead of one per state;
    - ``"direct"``: one compiled pass per state that reduces each weighted column against the
      others (:func:`~skhmmgmr._hmm._kernels.weighted_pair_sums`), with no array of products.

    Measured on one core (504,000 rows, AVX-512, OpenBLAS), "direct" is the faster for one or
    two accumulated states (the EM with K=2 or 3 states, whose heaviest state is taken as the
    remainder): 1.7x to 2.9x "pairs" over 4 to 8 columns, 1.4x over 12. It is also faster than
    one BLAS syrk per state of its ``sqrt(r)``-weighted columns, which served a lone state over
    8 columns or more before (1.7x over 8 columns, 1.3x over 20). From four states on "pairs"
    is the faster (1.2x to 1.7x over 8 to 14 columns).

    Parameters
    ----------
    n_states : int
    n_columns : int
        Number of augmented columns (features + 1).
    states : list of int, default=None
        States whose moments are accumulated (all when None); the others stay zero.
    method : {"direct", "pairs"}, default=None
        How the sums are computed; default: the faster one for these sizes (see above).
    sub_chunk : int, default=None
        Rows per sub-chunk of the pairwise products; default: as many as fit in
        :data:`PAIR_BUFFER_VALUES`.
    """

    def __init__(self, n_states, n_columns, states=None, method=None, sub_chunk=None):
        self.n_states = n_states
        self.n_columns = n_columns
        self.states = list(range(n_states)) if states is None else list(states)
        if method is None:
            method = "direct" if len(self.states) <= 2 else "pairs"
        if method not in ("pairs", "direct"):
            raise ValueError(f"method must be 'pairs' or 'direct', got {method!r}")
        self.method = method
        rows, cols = np.triu_indices(n_columns)
        self._pairs = (rows.astype(np.int64), cols.astype(np.int64))
        if sub_chunk is None:
            sub_chunk = max(PAIR_BUFFER_VALUES // len(rows), 256)
        self.sub_chunk = int(sub_chunk)
        self._buffer = None
        self._sums = np.zeros((len(self.states), len(rows)))

    def add(self, respT, columns, first=0):
        """Add one chunk: posteriors (n_states, n_rows) of the rows
        ``columns[:, first : first + n_rows]`` of augmented columns."""
        n_rows = respT.shape[1]
        if not columns.flags.c_contiguous:
            # the kernels need C-contiguous rows: copy this chunk only, never the whole array
            columns, first = np.ascontiguousarray(columns[:, first : first + n_rows]), 0
        if self.method == "pairs":
            self._add_pairs(respT, columns, first, n_rows)
        else:
            weights = respT if len(self.states) == self.n_states else respT[self.states]
            weighted_pair_sums(columns, first, np.ascontiguousarray(weights), self._sums)

    def add_pair_sums(self, sums):
        """Add moments already summed over rows: ``sums`` (len(states), n_pairs) holds, per
        accumulated state, the weighted sums of ``x_a x_b`` for the pairs ``a <= b`` in the
        order of :func:`numpy.triu_indices`."""
        self._sums += sums

    def _add_pairs(self, respT, columns, first, n_rows):
        n_pairs = len(self._pairs[0])
        step = min(self.sub_chunk, n_rows)
        if self._buffer is None or self._buffer.size < n_pairs * step:
            self._buffer = np.empty(n_pairs * step)
        weights = respT if len(self.states) == self.n_states else respT[self.states]
        for lo in range(0, n_rows, step):
            hi = min(lo + step, n_rows)
            products = self._buffer[: n_pairs * (hi - lo)].reshape(n_pairs, hi - lo)
            pairwise_products(columns, first + lo, *self._pairs, products)
            self._sums += weights[:, lo:hi] @ products.T

    def result(self):
        """The sums, shape (n_states, n_columns, n_columns)."""
        moments = np.zeros((self.n_states, self.n_columns, self.n_columns))
        rows, cols = self._pairs
        states = np.asarray(self.states, dtype=np.intp)[:, np.newaxis]
        moments[states, rows, cols] = self._sums
        moments[states, cols, rows] = self._sums
        return moments


def split_moments(moments):
    """``(weights, first, second)`` views of augmented moments (:class:`MomentSums`)."""
    n_features = moments.shape[1] - 1
    return (
        moments[:, n_features, n_features],
        moments[:, :n_features, n_features],
        moments[:, :n_features, :n_features],
    )


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
    sums = MomentSums(n_states, n_features + 1)
    step = chunk_size_for(n_states * n_features, chunk_size)
    for start in range(0, n_samples, step):
        rows = slice(start, start + step)
        sums.add(np.ascontiguousarray(resp[rows].T), augmented_columns(X[rows], shift))
    return split_moments(sums.result())


def gaussians_from_moments(weights, first, second, reg_covar, shift=None):
    """Means and covariances (with ``reg_covar`` on the diagonal) from raw moments.

    ``reg_covar`` is one value for every state or an array of shape (n_states,), one per
    state. ``weights`` must be strictly positive. The covariance is ``E[x x^T] - E[x] E[x]^T`` about
    the shift point; with the shift near the data (the engine uses the data mean, and the
    estimator standardises the data) the subtraction loses no significant digits.
    """
    n_features = first.shape[1]
    centred_means = first / weights[:, np.newaxis]
    covariances = second / weights[:, np.newaxis, np.newaxis]
    covariances -= centred_means[:, :, np.newaxis] * centred_means[:, np.newaxis, :]
    covariances += covariances.transpose(0, 2, 1)
    covariances *= 0.5
    diagonals = covariances.reshape(covariances.shape[0], -1)[:, :: n_features + 1]
    diagonals += np.reshape(np.asarray(reg_covar, dtype=float), (-1, 1))
    means = centred_means if shift is None else centred_means + shift
    return means, covariances
