"""Where an EM starts from a fitted model: the marginal of a joint model and a state split."""

import numpy as np
import pytest

from skhmmgmr._core._sequences import as_recordings
from skhmmgmr._hmm._em import HMMParameters, fit_hmm
from skhmmgmr._hmm._em_data import Columns
from skhmmgmr._hmm._em_start import (
    marginal_start,
    split_state,
    stationary_distribution,
    widest_state,
)


def random_parameters(rng, n_states, n_dims, covariance_type="full"):
    means = rng.normal(size=(n_states, n_dims))
    factors = rng.normal(size=(n_states, n_dims, n_dims))
    covariances = factors @ factors.transpose(0, 2, 1) + np.eye(n_dims)
    if covariance_type == "tied":
        covariances = covariances[0]
    transmat = rng.dirichlet(np.ones(n_states), size=n_states)
    startprob = rng.dirichlet(np.ones(n_states))
    return HMMParameters.gaussian(startprob, transmat, means, covariances, covariance_type)


def switching_data(seed=0, n_recordings=6, length=600):
    """Two regimes that switch slowly, each with its own linear map from the inputs to y."""
    rng = np.random.default_rng(seed)
    rows = []
    for _ in range(n_recordings):
        regime = np.cumsum(rng.random(length) < 0.01) % 2
        x = np.cumsum(rng.normal(scale=0.2, size=(length, 3)), axis=0)
        x -= x.mean(axis=0)
        slope = np.where(regime == 0, 2.0, -1.0)
        y = slope * x[:, 0] + 0.5 * x[:, 1] + 6.0 * regime + 0.1 * rng.normal(size=length)
        rows.append(np.column_stack([x, y]))
    data = np.vstack(rows)
    return Columns.from_rows((data - data.mean(axis=0)) / data.std(axis=0)), as_recordings(
        np.repeat(np.arange(n_recordings), length), n_recordings * length
    )


@pytest.mark.parametrize("covariance_type", ["full", "tied"])
def test_the_marginal_keeps_the_means_covariance_blocks_and_transitions(covariance_type):
    params = random_parameters(np.random.default_rng(0), 3, 5, covariance_type)
    dims = [3, 0, 4]
    start = marginal_start(params, dims)
    np.testing.assert_array_equal(start.means, params.means[:, dims])
    full = params.covariances
    np.testing.assert_array_equal(start.covariances, full[:, dims][:, :, dims])
    np.testing.assert_array_equal(start.transmat, params.transmat)
    np.testing.assert_array_equal(start.startprob, params.startprob)
    assert start.emissions.covariance_type == covariance_type
    start.transmat[0, 0] = -1.0  # a copy: the joint model is left alone
    assert params.transmat[0, 0] >= 0


def test_a_fit_from_the_marginal_reaches_the_optimum_of_a_cold_start():
    columns, recordings = switching_data()
    tol = 1e-4
    joint = fit_hmm(columns, recordings, 2, tol=1e-7, n_iter=500, random_state=0)
    dims = [0, 1, 3]  # inputs x0, x1 and the target y
    subset = Columns(np.ascontiguousarray(columns.values[[*dims, 4]]), np.zeros(3))
    cold = fit_hmm(subset, recordings, 2, tol=tol, n_iter=500, random_state=0)
    warm = fit_hmm(
        subset,
        recordings,
        2,
        tol=tol,
        n_iter=500,
        initial_parameters=marginal_start(joint.parameters, dims),
    )
    assert cold.converged and warm.converged
    # the same optimum to the convergence tolerance (per row), fewer iterations to reach it
    n_rows = subset.n_samples
    assert abs(warm.objective - cold.objective) < 10 * tol * n_rows
    assert warm.n_iter < cold.n_iter
    order = np.argsort(warm.parameters.means[:, -1])
    reference = np.argsort(cold.parameters.means[:, -1])
    np.testing.assert_allclose(
        warm.parameters.means[order], cold.parameters.means[reference], atol=0.02
    )


def test_the_stationary_distribution_is_left_fixed_by_the_transitions():
    transmat = random_parameters(np.random.default_rng(1), 4, 2).transmat
    weights = stationary_distribution(transmat)
    np.testing.assert_allclose(weights @ transmat, weights, atol=1e-12)
    assert weights.sum() == pytest.approx(1.0)
    # the long-run share of a chain's visits
    power = np.linalg.matrix_power(transmat, 200)
    np.testing.assert_allclose(power[0], weights, atol=1e-10)


def test_the_widest_state_holds_the_most_scatter():
    params = random_parameters(np.random.default_rng(2), 3, 2)
    transmat = np.full((3, 3), 1 / 3)  # equal weights: the widest covariance wins
    covariances = np.stack([np.eye(2), 9 * np.eye(2), 4 * np.eye(2)])
    params = HMMParameters.gaussian(params.startprob, transmat, params.means, covariances)
    assert widest_state(params) == 1


@pytest.mark.parametrize("covariance_type", ["full", "tied"])
def test_a_split_keeps_the_state_moments_and_the_chain(covariance_type):
    params = random_parameters(np.random.default_rng(3), 3, 4, covariance_type)
    grown = split_state(params, 1)
    assert grown.n_states == 4
    np.testing.assert_allclose(grown.transmat.sum(axis=1), 1.0)
    assert grown.startprob.sum() == pytest.approx(1.0)
    # the halves share the state's start and incoming transitions, and leave as it did
    assert grown.startprob[1] == grown.startprob[3] == pytest.approx(params.startprob[1] / 2)
    np.testing.assert_allclose(grown.transmat[:3, 1], params.transmat[:, 1] / 2)
    np.testing.assert_array_equal(grown.transmat[1], grown.transmat[3])
    # lumping the halves back gives the same chain
    lumped = grown.transmat[:3, :3].copy()
    lumped[:, 1] += grown.transmat[:3, 3]
    np.testing.assert_allclose(lumped, params.transmat)
    # the other states are untouched
    for k in (0, 2):
        np.testing.assert_array_equal(grown.means[k], params.means[k])
        np.testing.assert_array_equal(grown.covariances[k], params.covariances[k])
    # an equal mixture of the halves has the state's mean and covariance (full: exactly;
    # tied: the shared covariance stays, the means move apart along the principal axis)
    halves = grown.means[[1, 3]]
    np.testing.assert_allclose(halves.mean(axis=0), params.means[1])
    offset = 0.5 * (halves[1] - halves[0])
    variances, axes = np.linalg.eigh(params.covariances[1])
    assert abs(offset @ axes[:, -1]) == pytest.approx(0.5 * np.sqrt(variances[-1]))
    mixture = grown.covariances[[1, 3]].mean(axis=0) + np.outer(offset, offset)
    if covariance_type == "full":
        np.testing.assert_allclose(mixture, params.covariances[1], atol=1e-12)
    else:
        np.testing.assert_array_equal(grown.covariances[3], params.covariances[1])
    assert grown.emissions.covariance_type == covariance_type


def test_a_split_start_fits_one_more_state():
    columns, recordings = switching_data(seed=1)
    one = fit_hmm(columns, recordings, 1, tol=1e-6, n_iter=50, random_state=0)
    two = fit_hmm(
        columns, recordings, 2, tol=1e-6, n_iter=200, initial_parameters=split_state(one.parameters)
    )
    cold = fit_hmm(columns, recordings, 2, tol=1e-6, n_iter=200, random_state=0)
    # the split start finds the two regimes as the cold start does
    assert two.objective > one.objective + 0.1 * columns.n_samples
    assert abs(two.objective - cold.objective) < 1e-3 * columns.n_samples


def test_a_split_refuses_a_state_or_offset_out_of_range():
    params = random_parameters(np.random.default_rng(4), 2, 2)
    with pytest.raises(ValueError, match="state=2"):
        split_state(params, 2)
    with pytest.raises(ValueError, match="offset=1.5"):
        split_state(params, 0, offset=1.5)
