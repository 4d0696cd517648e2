"""Missing values marginalised by the model (``missing_values="marginalize"``), against plain
loops written here from the textbook formulas (scipy's multivariate normal on the observed
columns of every row, explicit loops over rows and states)."""

import numpy as np
import pandas as pd
import pytest
from scipy.stats import multivariate_normal
from test_portable import file_dict, load_dict

from skhmmgmr import FilterStream, HMMGMRRegressor
from skhmmgmr._core._sequences import Recordings
from skhmmgmr._hmm._em import HMMParameters, e_step, fit_hmm
from skhmmgmr._hmm._em_data import Columns, EStepData


def recordings_of(lengths):
    stops = np.cumsum(lengths)
    return Recordings(ids=np.arange(len(lengths)), starts=stops - np.asarray(lengths), stops=stops)


def with_gaps(X, rate, seed, full_rows=()):
    """A copy of ``X`` with a share ``rate`` of its values NaN, and rows ``full_rows`` all NaN."""
    rng = np.random.default_rng(seed)
    X = np.array(X, dtype=float)
    X[rng.random(X.shape) < rate] = np.nan
    X[list(full_rows)] = np.nan
    return X


def random_parameters(rng, n_states, n_dims):
    means = 2.0 * rng.normal(size=(n_states, n_dims))
    factors = rng.normal(size=(n_states, n_dims, n_dims))
    covariances = factors @ factors.transpose(0, 2, 1) + 0.5 * np.eye(n_dims)
    startprob = rng.dirichlet(np.ones(n_states))
    transmat = rng.dirichlet(np.ones(n_states) * 2, size=n_states)
    return startprob, transmat, means, covariances


# -- plain-loop references -----------------------------------------------------------------


def reference_expectations(X, lengths, startprob, transmat, means, covariances):
    """Forward-backward on the observed columns of every row; the expected statistics of the
    missing-data EM: per state ``N_k``, ``sum_t g E[x]`` and ``sum_t g E[x x^T]``."""
    n, d = X.shape
    K = len(startprob)
    frames = np.ones((n, K))
    completed = np.zeros((n, K, d))  # E[x_t | x_o, k]
    conditional = np.zeros((n, K, d, d))  # Cov[x_t | x_o, k] (on the missing block)
    for t in range(n):
        o = np.flatnonzero(~np.isnan(X[t]))
        m = np.flatnonzero(np.isnan(X[t]))
        for k in range(K):
            mu, S = means[k], covariances[k]
            if o.size:
                frames[t, k] = multivariate_normal(mu[o], S[np.ix_(o, o)]).pdf(X[t, o])
            gain = (
                S[np.ix_(m, o)] @ np.linalg.inv(S[np.ix_(o, o)])
                if o.size
                else np.zeros((m.size, 0))
            )
            completed[t, k, o] = X[t, o]
            completed[t, k, m] = mu[m] + gain @ (X[t, o] - mu[o])
            conditional[t, k][np.ix_(m, m)] = S[np.ix_(m, m)] - gain @ S[np.ix_(o, m)]
    log_likelihood = 0.0
    gamma = np.zeros((n, K))
    transitions = np.zeros((K, K))
    starts = np.zeros(K)
    first = 0
    for length in lengths:
        rows = range(first, first + length)
        alpha, beta, scale = np.zeros((length, K)), np.ones((length, K)), np.zeros(length)
        for i, t in enumerate(rows):
            for k in range(K):
                prior = (
                    startprob[k]
                    if i == 0
                    else sum(alpha[i - 1, j] * transmat[j, k] for j in range(K))
                )
                alpha[i, k] = prior * frames[t, k]
            scale[i] = alpha[i].sum()
            alpha[i] /= scale[i]
        for i in range(length - 2, -1, -1):
            t = first + i
            for j in range(K):
                beta[i, j] = sum(
                    transmat[j, k] * frames[t + 1, k] * beta[i + 1, k] for k in range(K)
                )
            beta[i] /= scale[i + 1]
        for i in range(length):
            gamma[first + i] = alpha[i] * beta[i]
        for i in range(length - 1):
            t = first + i
            for j in range(K):
                for k in range(K):
                    transitions[j, k] += (
                        alpha[i, j] * transmat[j, k] * frames[t + 1, k] * beta[i + 1, k]
                    ) / scale[i + 1]
        starts += gamma[first]
        log_likelihood += np.log(scale).sum()
        first += length
    weights = gamma.sum(axis=0)
    sums = np.einsum("tk,tkd->kd", gamma, completed)
    squares = np.zeros((K, d, d))
    for t in range(n):
        for k in range(K):
            squares[k] += gamma[t, k] * (
                np.outer(completed[t, k], completed[t, k]) + conditional[t, k]
            )
    return log_likelihood, starts, transitions, weights, sums, squares


def reference_predict(model, X):
    """The causal filter on the observed inputs of every row and GMR given them, in the
    data's units, from the joint means and covariances; one recording."""
    K, n_inputs = model.n_states, model.n_features_in_
    means, covariances = model.means_, model.covars_
    out_means, out_stds, alphas = [], [], []
    previous = None
    for t in range(X.shape[0]):
        o = np.flatnonzero(~np.isnan(X[t]))
        y = np.arange(n_inputs, means.shape[1])
        density, state_means, state_vars = np.ones(K), [], []
        for k in range(K):
            mu, S = means[k], covariances[k]
            if o.size:
                density[k] = multivariate_normal(mu[o], S[np.ix_(o, o)]).pdf(X[t, o])
                gain = S[np.ix_(y, o)] @ np.linalg.inv(S[np.ix_(o, o)])
                state_means.append(mu[y] + gain @ (X[t, o] - mu[o]))
                state_vars.append(np.diag(S[np.ix_(y, y)] - gain @ S[np.ix_(o, y)]))
            else:
                state_means.append(mu[y])
                state_vars.append(np.diag(S[np.ix_(y, y)]))
        if previous is None:
            prior = model.startprob_
        else:
            prior = np.array(
                [sum(previous[j] * model.transmat_[j, k] for j in range(K)) for k in range(K)]
            )
        alpha = prior * density
        alpha /= alpha.sum()
        estimate = sum(alpha[k] * state_means[k] for k in range(K))
        variance = sum(
            alpha[k] * (state_vars[k] + (state_means[k] - estimate) ** 2) for k in range(K)
        )
        out_means.append(estimate)
        out_stds.append(np.sqrt(variance))
        alphas.append(alpha)
        previous = alpha
    return np.array(out_means), np.array(out_stds), np.array(alphas)


# -- data ----------------------------------------------------------------------------------


def switching_data(n=240, n_outputs=1, seed=0):
    rng = np.random.default_rng(seed)
    X = np.cumsum(rng.normal(scale=0.3, size=(n, 3)), axis=0)
    y = np.where(X[:, 0] > 0, 1.5 * X[:, 0] - 0.5 * X[:, 1], -X[:, 0] + 0.3 * X[:, 2])
    y = y + rng.normal(scale=0.1, size=n)
    if n_outputs == 2:
        y = np.column_stack([y, np.sin(X[:, 1]) + rng.normal(scale=0.1, size=n)])
    groups = np.repeat(["a", "b"], n // 2)
    return X, y, groups


@pytest.fixture(scope="module")
def gappy_model():
    X, y, groups = switching_data()
    X = with_gaps(X, 0.15, seed=1, full_rows=[7, 130])
    y = with_gaps(y[:, np.newaxis], 0.1, seed=2)[:, 0]
    model = HMMGMRRegressor(n_states=3, missing_values="marginalize", random_state=0)
    return model.fit(X, y, groups=groups), X, y, groups


# -- the EM ---------------------------------------------------------------------------------


@pytest.mark.parametrize("block_size", [None, 16])
def test_e_step_matches_plain_loop_missing_data_em(block_size):
    rng = np.random.default_rng(3)
    lengths = [25, 30, 15]
    startprob, transmat, means, covariances = random_parameters(rng, 3, 4)
    X = with_gaps(rng.normal(size=(70, 4)) * 1.5, 0.25, seed=4, full_rows=[0, 33, 69])
    X[5] = [0.3, np.nan, np.nan, np.nan]
    expected = reference_expectations(X, lengths, startprob, transmat, means, covariances)
    log_likelihood, starts, transitions, weights, sums, squares = expected
    engine = EStepData(X, recordings_of(lengths), 3, chunk_size=7, block_size=block_size)
    assert engine.missing is not None and not np.isnan(engine.data.values).any()
    params = HMMParameters.gaussian(startprob, transmat, means, covariances)
    shift = engine.shift
    # twice: the second E-step takes one state's moments as the total minus the others'
    for _ in range(2):
        stats = e_step(engine, params)
        assert stats.log_likelihood == pytest.approx(log_likelihood, rel=1e-12)
        np.testing.assert_allclose(stats.start_counts, starts, rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(stats.transition_counts, transitions, rtol=1e-10, atol=1e-12)
        moments = stats.emission
        np.testing.assert_allclose(moments.weights, weights, rtol=1e-10)
        first = moments.first + moments.weights[:, np.newaxis] * shift
        np.testing.assert_allclose(first, sums, rtol=1e-10, atol=1e-10)
        second = (
            moments.second
            + moments.first[:, :, np.newaxis] * shift
            + shift[:, np.newaxis] * moments.first[:, np.newaxis, :]
            + moments.weights[:, np.newaxis, np.newaxis] * np.outer(shift, shift)
        )
        np.testing.assert_allclose(second, squares, rtol=1e-10, atol=1e-10)


@pytest.mark.parametrize("covariance_type", ["full", "tied"])
def test_one_em_iteration_matches_plain_loop_m_step(covariance_type):
    rng = np.random.default_rng(5)
    lengths = [40, 35]
    n_states, n_dims, reg_covar = 2, 3, 1e-2
    startprob, transmat, means, covariances = random_parameters(rng, n_states, n_dims)
    if covariance_type == "tied":
        covariances = np.repeat(covariances[:1], n_states, axis=0)
    X = with_gaps(rng.normal(size=(75, n_dims)) + 1.0, 0.2, seed=6, full_rows=[10])
    log_likelihood, starts, transitions, weights, sums, squares = reference_expectations(
        X, lengths, startprob, transmat, means, covariances
    )
    start = HMMParameters.gaussian(
        startprob,
        transmat,
        means,
        covariances if covariance_type == "full" else covariances[0],
        covariance_type,
    )
    result = fit_hmm(
        X,
        recordings_of(lengths),
        n_states,
        n_iter=1,
        reg_covar=reg_covar,
        initial_parameters=start,
        covariance_type=covariance_type,
    )
    assert result.history[0] == pytest.approx(log_likelihood, rel=1e-12)
    new_means = sums / weights[:, np.newaxis]
    scatter = squares - weights[:, np.newaxis, np.newaxis] * np.einsum(
        "ki,kj->kij", new_means, new_means
    )
    if covariance_type == "full":
        psi = reg_covar * len(X) / n_states
        new_covariances = (scatter + psi * np.eye(n_dims)) / weights[:, np.newaxis, np.newaxis]
    else:
        psi = reg_covar * len(X)
        shared = (scatter.sum(axis=0) + psi * np.eye(n_dims)) / weights.sum()
        new_covariances = np.repeat(shared[np.newaxis], n_states, axis=0)
    params = result.parameters
    np.testing.assert_allclose(params.startprob, starts / starts.sum(), rtol=1e-10)
    np.testing.assert_allclose(
        params.transmat, transitions / transitions.sum(axis=1, keepdims=True), rtol=1e-10
    )
    np.testing.assert_allclose(params.means, new_means, rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(params.covariances, new_covariances, rtol=1e-10, atol=1e-10)


def test_log_likelihood_in_data_units_matches_plain_loop(gappy_model):
    model, X, y, groups = gappy_model
    joint = np.column_stack([X, y])
    lengths = [int(np.sum(groups == g)) for g in pd.unique(groups)]
    expected = reference_expectations(
        joint, lengths, model.startprob_, model.transmat_, model.means_, model.covars_
    )[0]
    assert model.log_likelihood(X, y, groups=groups) == pytest.approx(expected, rel=1e-10)
    assert model.log_likelihood_ == pytest.approx(expected, rel=1e-10)


def test_complete_data_fit_is_the_same_with_either_setting():
    X, y, groups = switching_data()
    fits = [
        HMMGMRRegressor(n_states=3, missing_values=setting, random_state=0).fit(X, y, groups=groups)
        for setting in ("error", "marginalize")
    ]
    for name in ("startprob_", "transmat_", "means_", "covars_", "log_likelihood_history_"):
        np.testing.assert_allclose(getattr(fits[1], name), getattr(fits[0], name), rtol=1e-10)
    np.testing.assert_array_equal(
        fits[1].predict(X, groups=groups), fits[0].predict(X, groups=groups)
    )


def test_standardisation_ignores_missing_values():
    rng = np.random.default_rng(7)
    X = with_gaps(rng.normal(3.0, 2.0, size=(200, 3)), 0.3, seed=8)
    columns, center, scale = Columns.standardized(X[:, :2], X[:, 2:])
    np.testing.assert_allclose(center, np.nanmean(X, axis=0), rtol=1e-13)
    np.testing.assert_allclose(scale, np.nanstd(X, axis=0), rtol=1e-13)
    standardized = columns.values[:3].T
    np.testing.assert_array_equal(np.isnan(standardized), np.isnan(X))
    np.testing.assert_allclose(standardized, (X - center) / scale, rtol=1e-12, atol=1e-14)


def test_fit_with_missing_values_raises_the_objective_every_iteration(gappy_model):
    model = gappy_model[0]
    history = model.penalized_log_likelihood_history_
    assert np.all(np.diff(history) >= -1e-9 * np.abs(history).max())


# -- prediction -----------------------------------------------------------------------------


@pytest.mark.parametrize("n_outputs", [1, 2])
def test_predict_matches_plain_loop_filter_on_observed_inputs(n_outputs):
    X, y, _ = switching_data(n=160, n_outputs=n_outputs, seed=9)
    model = HMMGMRRegressor(n_states=3, missing_values="marginalize", random_state=0)
    model.fit(with_gaps(X, 0.1, seed=10), y)
    X_test = with_gaps(X[:60] + 0.2, 0.3, seed=11, full_rows=[0, 20, 21])
    expected_mean, expected_std, expected_alpha = reference_predict(model, X_test)
    estimate, std = model.predict(X_test, return_std=True)
    shape = (60,) if n_outputs == 1 else (60, 2)
    np.testing.assert_allclose(estimate, expected_mean.reshape(shape), rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(std, expected_std.reshape(shape), rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(model.predict_state_proba(X_test), expected_alpha, atol=1e-10)


def test_a_row_without_inputs_propagates_the_state_probabilities(gappy_model):
    model = gappy_model[0]
    X = np.full((3, 3), np.nan)
    alpha = model.predict_state_proba(X)
    np.testing.assert_allclose(alpha[0], model.startprob_, rtol=1e-12)
    np.testing.assert_allclose(alpha[1], model.startprob_ @ model.transmat_, rtol=1e-12)
    outputs = model.means_[:, 3]
    np.testing.assert_allclose(model.predict(X)[0], model.startprob_ @ outputs, rtol=1e-12)


def test_score_with_missing_inputs(gappy_model):
    model, X, _, groups = gappy_model
    X_complete, y_complete, _ = switching_data()
    assert model.score(X, y_complete, groups=groups) > 0.8
    assert model.score(X_complete, y_complete, groups=groups) > 0.9


# -- FilterStream ---------------------------------------------------------------------------


def test_stream_marginalises_like_predict(gappy_model):
    model, X, _, groups = gappy_model
    stream = model.filter_stream()
    assert stream.missing_values == "marginalize"
    expected, expected_std = model.predict(X, groups=groups, return_std=True)
    got, got_std, flags = [], [], []
    for recording in pd.unique(groups):
        stream.reset()
        for row in X[groups == recording]:
            estimate, std, flag = stream.update(row, return_std=True, return_flag=True)
            got.append(estimate)
            got_std.append(std)
            flags.append(flag)
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-12)
    np.testing.assert_allclose(got_std, expected_std, rtol=0, atol=1e-12)
    missing = np.isnan(X).any(axis=1)
    assert set(np.asarray(flags)[missing]) == {"missing"}
    assert set(np.asarray(flags)[~missing]) == {"ok"}
    batch = model.filter_stream().update_batch(X[groups == "a"])
    np.testing.assert_allclose(batch, expected[groups == "a"], rtol=0, atol=1e-12)


def test_stream_holds_missing_inputs_unless_they_are_marginalised(gappy_model):
    model, X, _, _ = gappy_model
    row = np.array([0.1, np.nan, 0.2])
    held = FilterStream(model.model_)  # a bare fitted model: "error", as before
    assert held.missing_values == "error"
    assert held.update(row, return_flag=True)[1] == "non-finite" and held.held_
    assert model.filter_stream(missing_values="error").update(row, return_flag=True)[1] == (
        "non-finite"
    )
    stream = FilterStream(model.model_, missing_values="marginalize")
    assert stream.update(row, return_flag=True)[1] == "missing" and not stream.held_
    # an infinity is not a missing value
    assert stream.update(np.array([np.inf, np.nan, 0.0]), return_flag=True)[1] == "non-finite"
    assert stream.update(np.array([1e300, np.nan, 0.0]), return_flag=True)[1] == "outlier"
    with pytest.raises(ValueError, match="missing_values must be"):
        FilterStream(model.model_, missing_values="drop")


# -- the estimator's interface --------------------------------------------------------------


def test_infinity_is_refused_naming_its_column_and_recording():
    X, y, groups = switching_data()
    X = with_gaps(X, 0.1, seed=12)
    X[130, 2] = np.inf
    model = HMMGMRRegressor(n_states=2, missing_values="marginalize")
    with pytest.raises(ValueError, match="infinity in column 'x2' of recording 'b'"):
        model.fit(X, y, groups=groups)
    y = y.copy()
    y[3] = -np.inf
    with pytest.raises(ValueError, match="y contains infinity in column 'output 0'"):
        model.fit(np.nan_to_num(X, posinf=0.0), y, groups=groups)


def test_a_column_never_observed_is_refused_by_name():
    X, y, groups = switching_data()
    X = pd.DataFrame(X, columns=["speed", "angle", "rate"])
    X["angle"] = np.nan
    model = HMMGMRRegressor(n_states=2, missing_values="marginalize")
    with pytest.raises(ValueError, match="column 'angle' is missing \\(NaN\\) in every row"):
        model.fit(X, y, groups=groups)


def test_missing_values_error_still_refuses_nan(gappy_model):
    _, X, y, groups = gappy_model
    with pytest.raises(ValueError, match="X contains NaN in column"):
        HMMGMRRegressor(n_states=2).fit(X, np.nan_to_num(y), groups=groups)
    with pytest.raises(ValueError, match="y contains NaN in column 'output 0'"):
        HMMGMRRegressor(n_states=2).fit(np.nan_to_num(X), y, groups=groups)


def test_tags_and_portable_model_keep_the_setting(gappy_model, tmp_path):
    model, X, _, groups = gappy_model
    assert model.__sklearn_tags__().input_tags.allow_nan
    assert not HMMGMRRegressor().__sklearn_tags__().input_tags.allow_nan
    restored = load_dict(file_dict(model, tmp_path), tmp_path)
    assert restored.missing_values == "marginalize"
    np.testing.assert_array_equal(
        restored.predict(X, groups=groups), model.predict(X, groups=groups)
    )
