"""Initial emissions of the EM, in the manner of ``sklearn.mixture``'s ``init_params``.

Every method gives each row responsibilities over the states (random soft ones, or hard ones
to the nearest of K centres found on a sample of the rows) and lets the emission family build
its first parameters from the moments they weight, with the same covariance prior the EM uses.
"""

import numpy as np
from numba import njit
from sklearn.cluster import KMeans, kmeans_plusplus

from ._emissions import MomentStatistics, emission_family
from ._gaussian import MomentSums, one_blas_thread, split_moments

INIT_METHODS = ("kmeans", "k-means++", "random", "random_from_data")

# The k-means initialisations cluster an evenly spaced sample of at most this many rows;
# every row then joins its nearest centre.
INIT_SAMPLE_ROWS = 100_000

# scikit-learn's KMeans defaults, which the compiled Lloyd iterations keep.
KMEANS_MAX_ITER = 300
KMEANS_TOL = 1e-4

# Rows per block of Lloyd's distance products (scikit-learn's chunk size).
LLOYD_BLOCK_ROWS = 256


def _init_sample(data, random_state):
    """The rows (about the shift) that the k-means initialisations cluster.

    All rows, or every ``step``-th row from a random offset: evenly spread over all
    recordings, and a slice that is copied without a gather.
    """
    if data.n_samples <= INIT_SAMPLE_ROWS:
        return data.rows()
    step = -(-data.n_samples // INIT_SAMPLE_ROWS)
    return data.rows(slice(random_state.randint(step), None, step))


def _kmeans_centers(sample, n_states, random_state):
    """Centres of ``KMeans(n_clusters=n_states, n_init=1, random_state=random_state)`` on
    ``sample`` (which is changed), computed here.

    The same algorithm and draws as scikit-learn's: k-means++ seeds (its
    :func:`~sklearn.cluster.kmeans_plusplus`) on the centred sample, then Lloyd's iterations
    until no label changes or the centres move by at most ``KMEANS_TOL`` times the mean
    variance. The result equals scikit-learn's on one thread to round-off (the tests compare
    them). It takes 12 ms where scikit-learn's call takes 24 (100,000 rows, K=2, 7 columns,
    one core), and less at every size tried up to K=20 over 13 columns: at these sizes the
    call's validation, copies and thread-pool set-up dominate, and the k-means was a sixth of
    a K=2 fit (issue #27). A cluster that empties is left to scikit-learn, which moves a far
    row into it, from the same random state.
    """
    mean = sample.mean(axis=0)
    sample -= mean
    squared_norms = np.einsum("ij,ij->i", sample, sample)
    tol = float(np.mean(np.einsum("ij,ij->j", sample, sample) / len(sample))) * KMEANS_TOL
    draws = random_state.get_state()
    seeds, _ = kmeans_plusplus(
        sample, n_states, x_squared_norms=squared_norms, random_state=random_state
    )
    with one_blas_thread():
        centers, complete = _lloyd(sample, np.ascontiguousarray(seeds), KMEANS_MAX_ITER, tol)
    if not complete:
        random_state.set_state(draws)
        kmeans = KMeans(n_clusters=n_states, n_init=1, random_state=random_state)
        centers = kmeans.fit(sample).cluster_centers_
    return centers + mean


@njit(cache=True, nogil=True)
def _lloyd(X, centers, max_iter, tol):
    """Lloyd's iterations from ``centers``; returns ``(centers, complete)``, ``complete``
    False when a cluster emptied (the caller starts again with scikit-learn).

    As scikit-learn's ``_kmeans_single_lloyd``: every row joins the centre with the smallest
    ``|c|^2 - 2 x.c`` (the first one on a tie), the centres become the means of their rows,
    and the loop stops when no label changed or the squared centre shifts sum to ``tol`` or
    less.
    """
    n_rows, n_columns = X.shape
    n_clusters = centers.shape[0]
    labels = np.full(n_rows, -1, dtype=np.int64)
    updated = np.empty_like(centers)
    weights = np.empty(n_clusters)
    center_norms = np.empty(n_clusters)
    for _ in range(max_iter):
        for j in range(n_clusters):
            center_norms[j] = 0.0
            for f in range(n_columns):
                center_norms[j] += centers[j, f] * centers[j, f]
        updated[:] = 0.0
        weights[:] = 0.0
        changed = False
        transposed = np.ascontiguousarray(centers.T)
        for lo in range(0, n_rows, LLOYD_BLOCK_ROWS):
            hi = min(lo + LLOYD_BLOCK_ROWS, n_rows)
            products = np.dot(X[lo:hi], transposed)
            for i in range(hi - lo):
                label = 0
                nearest = center_norms[0] - 2.0 * products[i, 0]
                for j in range(1, n_clusters):
                    distance = center_norms[j] - 2.0 * products[i, j]
                    if distance < nearest:
                        nearest = distance
                        label = j
                if labels[lo + i] != label:
                    changed = True
                    labels[lo + i] = label
                weights[label] += 1.0
                for f in range(n_columns):
                    updated[label, f] += X[lo + i, f]
        shift = 0.0
        for j in range(n_clusters):
            if weights[j] == 0.0:
                return centers, False
            inverse = 1.0 / weights[j]
            for f in range(n_columns):
                updated[j, f] *= inverse
                shift += (updated[j, f] - centers[j, f]) ** 2
        centers, updated = updated, centers
        if not changed or shift <= tol:
            break
    return centers, True


def _initial_moments(engine, n_states, responsibilities):
    """Moment statistics of the responsibilities ``responsibilities(lo, hi, chunk)`` returns
    for every chunk of rows, state-major.

    Every row's responsibilities sum to one, so the states' moments sum to those of all rows:
    the engine takes them as its totals (to round-off) instead of a pass of its own.
    """
    sums = MomentSums(n_states, engine.data.values.shape[0])
    for lo, hi, chunk in engine.chunks():
        sums.add(responsibilities(lo, hi, chunk), engine.data.values, lo)
    moments = sums.result()
    engine.adopt_totals(moments.sum(axis=0))
    return MomentStatistics(*split_moments(moments), engine.shift)


def _nearest_centre(centers):
    """Hard responsibilities: every row to its nearest centre (centres about the shift)."""
    n_states = centers.shape[0]
    half_norms = 0.5 * np.einsum("kf,kf->k", centers, centers)

    def responsibilities(lo, hi, chunk):
        respT = np.empty((n_states, hi - lo))
        _nearest_indicators(centers @ chunk[:-1], half_norms, respT)
        return respT

    return responsibilities


@njit(cache=True, nogil=True)
def _nearest_indicators(products, half_norms, out):
    """``out[k, t]`` = 1 for the state ``k`` with the smallest ``half_norms[k] - products[k, t]``
    (the first on a tie), 0 for the others: ``argmin_k |x_t - c_k|^2`` from ``c_k . x_t``.

    One pass instead of NumPy's subtraction, strided argmin and scatter (9 against 16 ms for
    504,000 rows, K=2; issue #27).
    """
    n_states, n_rows = products.shape
    for t in range(n_rows):
        label = 0
        nearest = half_norms[0] - products[0, t]
        for k in range(1, n_states):
            distance = half_norms[k] - products[k, t]
            if distance < nearest:
                nearest = distance
                label = k
        for k in range(n_states):
            out[k, t] = 0.0
        out[label, t] = 1.0


def initial_centers(data, n_states, init_params, random_state):
    """The K centres (about the shift) of the initialisations by centres (every method but
    ``"random"``), found on :func:`_init_sample`'s rows of ``data`` (anything with
    ``n_samples`` and ``rows(index)``, such as :class:`~skhmmgmr._hmm._em_data.Columns`)."""
    sample = _init_sample(data, random_state)
    if init_params == "kmeans":
        return _kmeans_centers(sample, n_states, random_state)
    if init_params == "k-means++":
        return kmeans_plusplus(sample, n_states, random_state=random_state)[0]
    return sample[random_state.choice(len(sample), size=n_states, replace=False)]


def centre_statistics(engine, centers):
    """Moment statistics of the rows ``engine`` holds, every row given to its nearest of the
    ``centers`` (about the shift); those of disjoint sets of rows merge."""
    return _initial_moments(engine, centers.shape[0], _nearest_centre(centers))


def initial_emissions(engine, n_states, init_params, reg_covar, random_state, covariance_type):
    """First emission parameters for the rows the E-step ``engine`` holds.

    ``engine`` gives the data (``data``, ``shift``, ``totals``) and its chunks of rows.
    """
    data = engine.data
    n_samples = data.n_samples
    if init_params == "random":
        resp = random_state.uniform(size=(n_samples, n_states))
        resp /= resp.sum(axis=1, keepdims=True)
        statistics = _initial_moments(
            engine, n_states, lambda lo, hi, chunk: np.ascontiguousarray(resp[lo:hi].T)
        )
    else:
        centers = initial_centers(data, n_states, init_params, random_state)
        statistics = centre_statistics(engine, centers)
    pooled = MomentStatistics(*split_moments(engine.totals[np.newaxis]), engine.shift)
    return emission_family(covariance_type).from_moments(statistics, reg_covar, pooled)
