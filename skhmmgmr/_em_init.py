"""Initial emissions of the EM, in the manner of ``sklearn.mixture``'s ``init_params``.

Every method gives each row responsibilities over the states (random soft ones, or hard ones
to the nearest of K centres found on a sample of the rows) and lets the emission family build
its first parameters from the moments they weight, with the same covariance prior the EM uses.
"""

import numpy as np
from sklearn.cluster import KMeans, kmeans_plusplus
from threadpoolctl import threadpool_limits

from ._emissions import MomentStatistics, emission_family
from ._gaussian import MomentSums, split_moments

INIT_METHODS = ("kmeans", "k-means++", "random", "random_from_data")

# The k-means initialisations cluster an evenly spaced sample of at most this many rows;
# every row then joins its nearest centre.
INIT_SAMPLE_ROWS = 100_000

# Below this many values (rows x columns) KMeans runs on one OpenMP thread.
SMALL_KMEANS_SIZE = 1_000_000


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
    # On small data the OpenMP thread start-up of KMeans costs far more than the clustering
    # (tens of milliseconds on a busy machine); one thread is faster there.
    threads = 1 if sample.size < SMALL_KMEANS_SIZE else None
    with threadpool_limits(limits=threads, user_api="openmp"):
        kmeans = KMeans(n_clusters=n_states, n_init=1, random_state=random_state)
        return kmeans.fit(sample).cluster_centers_


def _initial_moments(engine, n_states, responsibilities):
    """Moment statistics of the responsibilities ``responsibilities(lo, hi, chunk)`` returns
    for every chunk of rows, state-major."""
    sums = MomentSums(n_states, engine.data.values.shape[0])
    for lo, hi, chunk in engine.chunks():
        sums.add(responsibilities(lo, hi, chunk), engine.data.values, lo)
    return MomentStatistics(*split_moments(sums.result()), engine.shift)


def _nearest_centre(centers):
    """Hard responsibilities: every row to its nearest centre (centres about the shift)."""
    n_states = centers.shape[0]
    half_norms = 0.5 * np.einsum("kf,kf->k", centers, centers)[:, np.newaxis]

    def responsibilities(lo, hi, chunk):
        # argmin_k ||x - c_k||^2 = argmin_k (||c_k||^2 / 2 - c_k . x)
        labels = np.argmin(half_norms - centers @ chunk[:-1], axis=0)
        respT = np.zeros((n_states, hi - lo))
        respT[labels, np.arange(hi - lo)] = 1.0
        return respT

    return responsibilities


def initial_centers(data, n_states, init_params, random_state):
    """The K centres (about the shift) of the initialisations by centres (every method but
    ``"random"``), found on :func:`_init_sample`'s rows of ``data`` (anything with
    ``n_samples`` and ``rows(index)``, such as :class:`~skhmmgmr._em_data.Columns`)."""
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
