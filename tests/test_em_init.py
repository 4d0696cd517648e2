"""The compiled k-means of the initialisation against scikit-learn's KMeans."""

import warnings

import numpy as np
import pytest
from sklearn.cluster import KMeans
from threadpoolctl import threadpool_limits

from skhmmgmr._hmm._em_init import _kmeans_centers


def sklearn_centers(sample, n_states, random_state):
    with threadpool_limits(limits=1), warnings.catch_warnings():
        warnings.simplefilter("ignore")  # fewer distinct clusters than n_states
        kmeans = KMeans(n_clusters=n_states, n_init=1, random_state=random_state)
        return kmeans.fit(sample).cluster_centers_


def blobs(rng, n_states, n_columns, n_rows):
    centres = rng.normal(scale=3.0, size=(n_states, n_columns))
    rows = centres[rng.integers(n_states, size=n_rows)] + rng.normal(size=(n_rows, n_columns))
    return rows + 5.0  # not centred: the function centres it as KMeans does


@pytest.mark.parametrize(
    ("n_states", "n_columns", "n_rows"),
    [(1, 3, 50), (2, 7, 20_000), (3, 2, 3_000), (5, 4, 10_000), (12, 13, 6_000)],
)
def test_kmeans_centers_equal_sklearn_and_use_the_same_draws(n_states, n_columns, n_rows):
    sample = blobs(np.random.default_rng(n_states), n_states, n_columns, n_rows)
    ours_state, theirs_state = np.random.RandomState(7), np.random.RandomState(7)
    theirs = sklearn_centers(sample, n_states, theirs_state)
    ours = _kmeans_centers(sample.copy(), n_states, ours_state)
    np.testing.assert_allclose(ours, theirs, rtol=0, atol=1e-10 * np.abs(sample).max())
    # the EM draws its transition matrix from the same state next
    assert ours_state.randint(1 << 30) == theirs_state.randint(1 << 30)


def test_kmeans_centers_equal_sklearn_after_many_iterations():
    # a uniform square has no clusters: sklearn takes 25 iterations here
    sample = np.random.default_rng(0).uniform(size=(20_000, 2))
    theirs = sklearn_centers(sample, 9, np.random.RandomState(0))
    ours = _kmeans_centers(sample.copy(), 9, np.random.RandomState(0))
    np.testing.assert_allclose(ours, theirs, atol=1e-12)


def test_an_emptied_cluster_is_left_to_sklearn_from_the_same_draws():
    # three distinct rows for five clusters: k-means++ seeds duplicates, a cluster empties
    sample = np.repeat([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]], [40, 30, 30], axis=0)
    ours_state, theirs_state = np.random.RandomState(1), np.random.RandomState(1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ours = _kmeans_centers(sample.copy(), 5, ours_state)
    theirs = sklearn_centers(sample, 5, theirs_state)
    np.testing.assert_allclose(ours, theirs, atol=1e-12)
    assert ours_state.randint(1 << 30) == theirs_state.randint(1 << 30)


def test_nearest_indicators_pick_the_nearest_centre_first_on_ties():
    from skhmmgmr._hmm._em_init import _nearest_indicators

    rng = np.random.default_rng(2)
    centers = rng.normal(size=(4, 3))
    rows = rng.normal(size=(500, 3))
    rows[:4] = centers  # each exactly on a centre
    centers[3] = centers[1]  # a duplicate centre: every tie goes to the first
    half_norms = 0.5 * np.einsum("kf,kf->k", centers, centers)
    out = np.full((4, 500), np.nan)
    _nearest_indicators(centers @ rows.T, half_norms, out)
    distances = ((rows[:, np.newaxis, :] - centers[np.newaxis]) ** 2).sum(axis=2)
    expected = np.zeros((4, 500))
    expected[np.argmin(distances, axis=1), np.arange(500)] = 1.0
    np.testing.assert_array_equal(out, expected)
    assert out[3].sum() == 0.0  # the duplicate never wins


@pytest.mark.parametrize("init_params", ["kmeans", "random"])
def test_initial_moments_give_the_engine_its_totals(init_params):
    from skhmmgmr._core._sequences import as_recordings
    from skhmmgmr._hmm._em import initialize_parameters
    from skhmmgmr._hmm._em_data import EStepData

    rng = np.random.default_rng(4)
    X = blobs(rng, 3, 4, 3_000)
    recordings = as_recordings(np.repeat([0, 1, 2], 1_000), len(X))
    adopted = EStepData(X, recordings, 3)
    initialize_parameters(
        None, recordings, 3, init_params, 1e-6, np.random.RandomState(0), engine=adopted
    )
    computed = EStepData(X, recordings, 3).totals  # its own pass over the rows
    # the first moments are about the column means: zero up to round-off
    np.testing.assert_allclose(adopted.totals, computed, atol=1e-12 * np.abs(computed).max())
    assert adopted.totals[-1, -1] == len(X)  # the weight of all rows
