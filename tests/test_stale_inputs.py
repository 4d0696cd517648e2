"""Missing inputs read through their last observed value (``missing_values="carry_forward"``),
against plain loops written here from the textbook formulas: the joint Gaussian of a row's
observed inputs and its carried values (state covariance plus the carried values' noise on
the diagonal), scipy's multivariate normal for its density and explicit conditioning for the
regression."""

import pickle

import numpy as np
import pandas as pd
import pytest
from scipy.stats import multivariate_normal
from test_missing import random_parameters, switching_data, with_gaps
from test_portable import file_dict, load_dict

from skhmmgmr import FilterStream, FittedHMMGMR, HMMGMRRegressor
from skhmmgmr._hmm._emissions import make_emissions
from skhmmgmr._hmm._missing import condition_rows
from skhmmgmr._hmm._stale_inputs import StaleInputNoise, last_observed

# -- plain-loop references -----------------------------------------------------------------


def reference_last_observed(X, groups):
    carried, gaps = np.full(X.shape, np.nan), np.zeros(X.shape, dtype=int)
    for j in range(X.shape[1]):
        last, seen_at, recording = np.nan, None, None
        for t in range(X.shape[0]):
            if groups[t] != recording:
                last, seen_at, recording = np.nan, None, groups[t]
            if not np.isnan(X[t, j]):
                last, seen_at = X[t, j], t
            elif seen_at is not None:
                carried[t, j], gaps[t, j] = last, t - seen_at
    return carried, gaps


def reference_variogram(X, groups, lag):
    out = []
    for j in range(X.shape[1]):
        squares = [
            (X[t, j] - X[t - lag, j]) ** 2
            for t in range(lag, X.shape[0])
            if groups[t] == groups[t - lag]
            and not np.isnan(X[t, j])
            and not np.isnan(X[t - lag, j])
        ]
        out.append(np.mean(squares) if squares else np.inf)
    return np.array(out)


def reference_noise(noise, gap, j, scale=1.0):
    """Variance of a value carried ``gap`` samples, by a loop over the table (data units)."""
    lags, variances = noise.lags, noise.variances[j]
    if gap < 1 or gap > lags[-1]:
        return np.inf
    i = np.searchsorted(lags, gap)
    if lags[i] == gap:
        value = variances[i]
    else:
        w = (gap - lags[i - 1]) / (lags[i] - lags[i - 1])
        value = (1 - w) * variances[i - 1] + w * variances[i]
    return value * scale**2


def reference_conditioning(x, carried, noise, mu, S, outputs=()):
    """Density of a row's observed values and carried values (noise variances ``noise``, inf
    for none) under N(mu, S), and the mean and covariance of the columns ``outputs`` and of the
    missing columns given both."""
    o = np.flatnonzero(~np.isnan(x))
    c = np.flatnonzero(np.isnan(x) & np.isfinite(noise))
    seen = np.concatenate([o, c])
    value = np.concatenate([x[o], carried[c]])
    cov = S[np.ix_(seen, seen)] + np.diag(np.concatenate([np.zeros(o.size), noise[c]]))
    density = multivariate_normal(mu[seen], cov).pdf(value) if seen.size else 1.0
    targets = np.concatenate([np.flatnonzero(np.isnan(x)), np.asarray(outputs, dtype=int)])
    if seen.size:
        gain = S[np.ix_(targets, seen)] @ np.linalg.inv(cov)
        mean = mu[targets] + gain @ (value - mu[seen])
        covariance = S[np.ix_(targets, targets)] - gain @ S[np.ix_(seen, targets)]
    else:
        mean, covariance = mu[targets], S[np.ix_(targets, targets)]
    return density, mean, covariance


def reference_predict(model, X, groups):
    """The causal filter of a carry-forward model by plain loops, in the data's units."""
    K, n_inputs = model.n_states, model.n_features_in_
    means, covariances = model.means_, model.covars_
    noise, scale = model.model_.stale_noise, model.model_.standardization.input_scale
    carried, gaps = reference_last_observed(X, groups)
    y = np.arange(n_inputs, means.shape[1])
    estimates, stds = [], []
    previous = None
    for t in range(X.shape[0]):
        if t == 0 or groups[t] != groups[t - 1]:
            previous = None
        variances = np.array(
            [reference_noise(noise, gaps[t, j], j, scale[j]) for j in range(n_inputs)]
        )
        density, state_means, state_vars = np.ones(K), [], []
        for k in range(K):
            full = np.concatenate([X[t], np.full(y.size, np.nan)])
            d, mean, cov = reference_conditioning(
                X[t],
                carried[t],
                variances,
                means[k][:n_inputs],
                covariances[k][:n_inputs, :n_inputs],
            )
            density[k] = d
            # the outputs given the same observations: condition the joint Gaussian
            d, mean, cov = reference_conditioning(
                full,
                np.concatenate([carried[t], np.zeros(y.size)]),
                np.concatenate([variances, np.full(y.size, np.inf)]),
                means[k],
                covariances[k],
            )
            state_means.append(mean[-y.size :])
            state_vars.append(np.diag(cov)[-y.size :])
        prior = model.startprob_ if previous is None else previous @ model.transmat_
        alpha = prior * density
        alpha /= alpha.sum()
        estimate = sum(alpha[k] * state_means[k] for k in range(K))
        variance = sum(
            alpha[k] * (state_vars[k] + (state_means[k] - estimate) ** 2) for k in range(K)
        )
        estimates.append(estimate[0])
        stds.append(np.sqrt(variance[0]))
        previous = alpha
    return np.array(estimates), np.array(stds)


# -- the pieces ----------------------------------------------------------------------------


def test_last_observed_matches_a_plain_loop():
    rng = np.random.default_rng(0)
    X = with_gaps(rng.normal(size=(60, 3)), 0.4, seed=1)
    X[20:26, 1] = np.nan  # a long gap across the start of recording 1 at row 25
    groups = np.repeat([0, 1, 2], [25, 20, 15])
    stops = np.cumsum([25, 20, 15])
    carried, gaps = last_observed(X, stops - [25, 20, 15], stops)
    expected_carried, expected_gaps = reference_last_observed(X, groups)
    np.testing.assert_array_equal(gaps, expected_gaps)
    np.testing.assert_array_equal(carried, expected_carried)
    assert np.isnan(carried[25, 1]) or not np.isnan(X[25, 1])  # never across recordings


def test_variogram_matches_a_plain_loop_within_recordings():
    rng = np.random.default_rng(2)
    X = with_gaps(np.cumsum(rng.normal(size=(90, 2)), axis=0), 0.2, seed=3)
    X[:, 1] = np.where(np.arange(90) % 2, np.nan, X[:, 1])  # only even lags seen in column 1
    lengths = np.array([40, 30, 20])
    groups = np.repeat([0, 1, 2], lengths)
    stops = np.cumsum(lengths)
    noise = StaleInputNoise.learn(X, stops - lengths, stops)
    assert noise.lags[-1] < 40  # lags longer than every recording are not tabulated
    for i, lag in enumerate(noise.lags):
        np.testing.assert_allclose(noise.variances[:, i], reference_variogram(X, groups, lag))
    assert np.isinf(noise.variances[1, 0]) and np.isfinite(noise.variances[1, 1])


def test_precisions_interpolate_the_table():
    noise = StaleInputNoise(np.array([1, 2, 4]), np.array([[1.0, 2.0, 4.0], [0.5, np.inf, 1.0]]))
    gaps = np.array([[0, 1], [3, 1], [4, 2], [5, 3]])
    expected = np.array([[0.0, 2.0], [1 / 3, 2.0], [1 / 4, 0.0], [0.0, 0.0]])
    np.testing.assert_allclose(noise.precisions(gaps), expected)


def test_conditioning_on_carried_values_matches_the_joint_gaussian():
    rng = np.random.default_rng(4)
    K, D, n = 3, 4, 40
    _, _, means, covariances = random_parameters(rng, K, D)
    emissions = make_emissions("full", means, covariances)
    x = rng.normal(size=(n, D)) * 2
    missing = rng.random((n, D)) < 0.5
    missing[0], missing[1] = True, False  # a row with nothing observed, a complete row
    carried = rng.normal(size=(n, D))
    noise = np.where(rng.random((n, D)) < 0.7, rng.uniform(0.05, 3.0, size=(n, D)), np.inf)
    weights = np.where(missing & np.isfinite(noise), 1.0 / noise, 0.0)
    got = condition_rows(
        emissions,
        np.where(missing, 0.0, x),
        missing,
        stale=(np.where(weights > 0, carried, 0.0), weights),
    )
    for t in range(n):
        row = np.where(missing[t], np.nan, x[t])
        variances = np.where(weights[t] > 0, noise[t], np.inf)
        m = np.flatnonzero(missing[t])
        for k in range(K):
            density, mean, cov = reference_conditioning(
                row, carried[t], variances, means[k], covariances[k]
            )
            np.testing.assert_allclose(got.log_prob[t, k], np.log(density), rtol=1e-10)
            np.testing.assert_allclose(got.deltas[k, t, m], mean, rtol=1e-10, atol=1e-10)
            for rows, _columns, covs in got.groups:
                where = np.flatnonzero(rows == t)
                if where.size:
                    np.testing.assert_allclose(covs[k, where[0]], cov, rtol=1e-10, atol=1e-10)


def test_no_carried_value_is_marginalisation_and_an_exact_one_is_forward_fill():
    rng = np.random.default_rng(5)
    _, _, means, covariances = random_parameters(rng, 2, 3)
    emissions = make_emissions("full", means, covariances)
    x = rng.normal(size=(10, 3))
    missing = np.zeros((10, 3), dtype=bool)
    missing[:, 1] = True
    zero = condition_rows(emissions, x * ~missing, missing, stale=(x, np.zeros((10, 3))))
    plain = condition_rows(emissions, x * ~missing, missing)
    np.testing.assert_array_equal(zero.log_prob, plain.log_prob)
    exact = condition_rows(emissions, x * ~missing, missing, stale=(x, missing * 1e12))
    np.testing.assert_allclose(exact.deltas[:, :, 1], np.broadcast_to(x[:, 1], (2, 10)), atol=1e-9)


# -- the estimator and the stream -----------------------------------------------------------


@pytest.fixture(scope="module")
def carry_model():
    X, y, groups = switching_data(n=200, seed=6)
    X = with_gaps(X, 0.2, seed=7)
    X[40:52, 0] = np.nan  # an outage of 12 samples
    model = HMMGMRRegressor(n_states=3, missing_values="carry_forward", random_state=0)
    return model.fit(X, y, groups=groups), X, y, groups


def test_fit_is_the_missing_data_em_plus_the_variograms(carry_model):
    model, X, y, groups = carry_model
    plain = HMMGMRRegressor(n_states=3, missing_values="marginalize", random_state=0)
    plain.fit(X, y, groups=groups)
    np.testing.assert_array_equal(model.means_, plain.means_)
    np.testing.assert_array_equal(model.transmat_, plain.transmat_)
    assert plain.model_.stale_noise is None
    scaling = model.model_.standardization
    Z = scaling.inputs(X)
    for i, lag in enumerate(model.model_.stale_noise.lags):
        np.testing.assert_allclose(
            model.model_.stale_noise.variances[:, i], reference_variogram(Z, groups, lag)
        )


def test_predict_matches_a_plain_loop(carry_model):
    model, X, _, groups = carry_model
    X_test = with_gaps(switching_data(n=120, seed=8)[0], 0.3, seed=9, full_rows=[0, 61])
    X_test[70:90, 2] = np.nan
    groups_test = np.repeat(["u", "v"], 60)
    expected, expected_std = reference_predict(model, X_test, groups_test)
    estimate, std = model.predict(X_test, groups=groups_test, return_std=True)
    np.testing.assert_allclose(estimate, expected, rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(std, expected_std, rtol=1e-10, atol=1e-10)
    marginalized = model.set_params(missing_values="marginalize").predict(
        X_test, groups=groups_test
    )
    model.set_params(missing_values="carry_forward")
    assert np.abs(marginalized - estimate).max() > 1e-3  # the carried values count


def test_stream_carries_like_predict_and_restarts_with_the_recording(carry_model, tmp_path):
    model, X, _, groups = carry_model
    expected, expected_std = model.predict(X, groups=groups, return_std=True)
    for stream in (
        model.filter_stream(),
        pickle.loads(pickle.dumps(model.filter_stream())),
        load_dict(file_dict(model, tmp_path), tmp_path).filter_stream(),
    ):
        assert stream.missing_values == "carry_forward"
        got, got_std = [], []
        for recording in pd.unique(groups):
            stream.reset()
            for row in X[groups == recording]:
                estimate, std = stream.update(row, return_std=True)
                got.append(estimate)
                got_std.append(std)
        np.testing.assert_allclose(got, expected, rtol=0, atol=1e-12)
        np.testing.assert_allclose(got_std, expected_std, rtol=0, atol=1e-12)


def test_portable_model_keeps_the_variograms(carry_model, tmp_path):
    model, X, _, groups = carry_model
    data = file_dict(model, tmp_path)
    assert len(data["stale_inputs"]["variances"]) == 3
    restored = load_dict(data, tmp_path)
    assert restored.missing_values == "carry_forward"
    np.testing.assert_array_equal(
        restored.model_.stale_noise.variances, model.model_.stale_noise.variances
    )
    np.testing.assert_array_equal(
        restored.predict(X, groups=groups), model.predict(X, groups=groups)
    )
    data["stale_inputs"]["variances"][0][0] = None  # unknown: marginalised
    assert np.isinf(load_dict(data, tmp_path).model_.stale_noise.variances[0, 0])
    data["stale_inputs"]["variances"][0][0] = -1.0
    with pytest.raises(ValueError, match="stale_noise.variances must be at least"):
        load_dict(data, tmp_path)


def test_adapted_models_keep_the_variograms(carry_model):
    model, X, y, groups = carry_model
    adapted = HMMGMRRegressor.from_fitted_model(model.model_, missing_values="carry_forward")
    adapted.adapt(X, y, groups=groups, relevance=16.0)
    assert adapted.model_.stale_noise is model.model_.stale_noise or np.array_equal(
        adapted.model_.stale_noise.variances, model.model_.stale_noise.variances
    )
    stream = model.filter_stream(relevance=16.0)
    stream.update_batch(X[:50], y=y[:50])
    assert stream.adapted_model().stale_noise is not None


def test_carry_forward_needs_the_variograms(carry_model):
    model, X, y, groups = carry_model
    plain = HMMGMRRegressor(n_states=2, missing_values="marginalize", random_state=0)
    plain.fit(X, y, groups=groups)
    with pytest.raises(
        ValueError, match="needs a model fitted with missing_values='carry_forward'"
    ):
        FilterStream(plain.model_, missing_values="carry_forward")
    with pytest.raises(ValueError, match="stale_noise is None"):
        plain.set_params(missing_values="carry_forward").predict(X, groups=groups)
    assert plain.__sklearn_tags__().input_tags.allow_nan
    with pytest.raises(ValueError, match="stale_noise.variances must be"):
        FittedHMMGMR(
            model.model_.startprob,
            model.model_.transmat,
            model.model_.data_emissions,
            model.model_.standardization,
            stale_noise=StaleInputNoise(np.array([1, 2]), np.ones((2, 2))),
        )


def test_predict_ahead_carries_like_predict(carry_model):
    model, X, _, groups = carry_model
    expected, expected_std = model.predict(X, groups=groups, return_std=True)
    now, now_std = model.predict_ahead(X, 0, groups=groups, return_std=True)
    np.testing.assert_allclose(now, expected, rtol=0, atol=1e-12)
    np.testing.assert_allclose(now_std, expected_std, rtol=0, atol=1e-12)
    # rows shuffled, recordings and time in the index: the carried values follow time order
    frame = pd.DataFrame(
        X,
        index=pd.MultiIndex.from_arrays(
            [groups, np.tile(np.arange(100) * 0.05, 2)], names=["recording", "time"]
        ),
    )
    order = np.random.default_rng(10).permutation(len(frame))
    shuffled = model.predict_ahead(frame.iloc[order], 0)
    np.testing.assert_allclose(shuffled, expected[order], rtol=0, atol=1e-12)
    ahead = model.predict_ahead(frame.iloc[order], 5, state_output="conditional")
    np.testing.assert_allclose(
        ahead, model.predict_ahead(X, 5, groups=groups, state_output="conditional")[order]
    )
