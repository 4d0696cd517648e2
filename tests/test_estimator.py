"""HMMGMRRegressor against independent references: plain loops, hmmlearn, hand-made cases."""

import math

import numpy as np
import pytest
from hmmlearn.hmm import GaussianHMM
from scipy.stats import multivariate_normal

from skhmmgmr import HMMGMRRegressor
from skhmmgmr._core._sequences import as_recordings
from skhmmgmr._hmm._em import HMMParameters, fit_hmm


def make_switching_data(n_recordings=3, length=150, seed=0):
    """Two regimes with different input-output gains, told apart by the inputs."""
    rng = np.random.default_rng(seed)
    X_parts, y_parts, groups = [], [], []
    for r in range(n_recordings):
        x = np.cumsum(rng.normal(scale=0.3, size=(length, 2)), axis=0)
        y = np.where(x[:, 0] > 0, 1.5 * x[:, 0] - 0.5 * x[:, 1], -x[:, 0] + 0.3 * x[:, 1])
        y = y + rng.normal(scale=0.1, size=length)
        X_parts.append(x)
        y_parts.append(y)
        groups += [f"rec{r}"] * length
    return np.vstack(X_parts), np.concatenate(y_parts), np.asarray(groups)


@pytest.fixture(scope="module")
def data():
    return make_switching_data()


@pytest.fixture(scope="module")
def fitted(data):
    X, y, groups = data
    return HMMGMRRegressor(n_states=3, random_state=0).fit(X, y, groups=groups)


def reference_filter(model, X, n_inputs):
    """Plain-loop forward recursion on the inputs and GMR (METHOD.md section 2)."""
    K = model.startprob_.shape[0]
    means, covs = model.means_, model.covars_
    estimates, variances, alphas = [], [], []
    previous = None
    for t in range(X.shape[0]):
        f = X[t]
        b = [
            multivariate_normal(means[k, :n_inputs], covs[k, :n_inputs, :n_inputs]).pdf(f)
            for k in range(K)
        ]
        if previous is None:
            unnormalised = [model.startprob_[k] * b[k] for k in range(K)]
        else:
            unnormalised = [
                sum(previous[j] * model.transmat_[j, k] for j in range(K)) * b[k] for k in range(K)
            ]
        total = sum(unnormalised)
        alpha = [u / total for u in unnormalised]
        m, v = [], []
        for k in range(K):
            s_ff = covs[k, :n_inputs, :n_inputs]
            s_tf = covs[k, n_inputs:, :n_inputs]
            gain = s_tf @ np.linalg.inv(s_ff)
            m.append(means[k, n_inputs] + (gain @ (f - means[k, :n_inputs]))[0])
            v.append(covs[k, n_inputs, n_inputs] - (gain @ s_tf.T)[0, 0])
        estimate = sum(alpha[k] * m[k] for k in range(K))
        variance = sum(alpha[k] * (v[k] + m[k] ** 2) for k in range(K)) - estimate**2
        estimates.append(estimate)
        variances.append(variance)
        alphas.append(alpha)
        previous = alpha
    return np.array(estimates), np.sqrt(np.array(variances)), np.array(alphas)


def test_predict_matches_plain_loop_reference(data, fitted):
    X, _, groups = data
    pred, std = fitted.predict(X, groups=groups, return_std=True)
    alpha = fitted.predict_state_proba(X, groups=groups)
    for rec in np.unique(groups):
        rows = groups == rec
        ref_pred, ref_std, ref_alpha = reference_filter(fitted, X[rows], n_inputs=2)
        np.testing.assert_allclose(pred[rows], ref_pred, rtol=0, atol=1e-10)
        np.testing.assert_allclose(std[rows], ref_std, rtol=0, atol=1e-10)
        np.testing.assert_allclose(alpha[rows], ref_alpha, rtol=0, atol=1e-10)


def test_filter_restarts_at_every_recording(data, fitted):
    X, _, groups = data
    together = fitted.predict(X, groups=groups)
    separately = np.concatenate([fitted.predict(X[groups == r]) for r in np.unique(groups)])
    np.testing.assert_allclose(together, separately, rtol=0, atol=1e-12)
    as_one_sequence = fitted.predict(X)
    assert not np.allclose(as_one_sequence, together)


def test_filter_is_causal(data, fitted):
    X, _, _ = data
    full = fitted.predict(X[:100])
    truncated = fitted.predict(X[:60])
    np.testing.assert_allclose(full[:60], truncated, rtol=0, atol=1e-12)


def test_log_likelihood_matches_hmmlearn_score(data, fitted):
    X, y, groups = data
    peer = GaussianHMM(n_components=3, covariance_type="full", init_params="", params="")
    peer.startprob_ = fitted.startprob_
    peer.transmat_ = fitted.transmat_
    peer.means_ = fitted.means_
    peer.covars_ = fitted.covars_
    lengths = [int((groups == r).sum()) for r in np.unique(groups)]
    expected = peer.score(np.column_stack([X, y]), lengths=lengths)
    assert fitted.log_likelihood(X, y, groups=groups) == pytest.approx(expected, rel=1e-10)
    assert fitted.log_likelihood_ == pytest.approx(expected, rel=1e-10)


def test_em_iterations_match_hmmlearn(data):
    """Same starting parameters, no regularisation: same parameters and log-likelihoods."""
    X, y, groups = data
    joint = np.column_stack([X, y])
    recordings = as_recordings(groups, len(joint))
    rng = np.random.default_rng(1)
    K, D = 3, joint.shape[1]
    start = HMMParameters.gaussian(
        startprob=np.array([0.5, 0.3, 0.2]),
        transmat=rng.dirichlet(np.ones(K) * 5, size=K),
        means=joint[rng.choice(len(joint), K, replace=False)],
        covariances=np.stack([np.cov(joint.T)] * K),
    )
    ours = fit_hmm(joint, recordings, K, n_iter=5, tol=0.0, reg_covar=0.0, initial_parameters=start)
    peer = GaussianHMM(
        n_components=K,
        covariance_type="full",
        n_iter=5,
        tol=0.0,
        init_params="",
        covars_prior=np.zeros((K, D, D)),
        covars_weight=0,
    )
    peer.startprob_ = start.startprob.copy()
    peer.transmat_ = start.transmat.copy()
    peer.means_ = start.means.copy()
    peer.covars_ = start.covariances.copy()
    peer.fit(joint, lengths=list(recordings.lengths))
    np.testing.assert_allclose(ours.history[:5], peer.monitor_.history, rtol=1e-9)
    np.testing.assert_allclose(ours.parameters.means, peer.means_, rtol=1e-7, atol=1e-9)
    np.testing.assert_allclose(ours.parameters.covariances, peer.covars_, rtol=1e-7, atol=1e-9)
    np.testing.assert_allclose(ours.parameters.transmat, peer.transmat_, rtol=1e-7, atol=1e-12)


def assert_non_decreasing(history):
    history = np.asarray(history)
    assert np.all(np.isfinite(history))
    drops = -np.diff(history)
    assert drops.max() <= 1e-9 * np.abs(history).max(), drops.max()


def test_exactly_collinear_and_constant_columns(data):
    X, y, groups = data
    speed = 27.8
    lateral_velocity = X[:, 0]
    X_bad = np.column_stack([X, lateral_velocity / speed, np.full(len(X), 27.8)])
    model = HMMGMRRegressor(n_states=3, random_state=0, n_iter=200).fit(X_bad, y, groups=groups)
    assert_non_decreasing(model.penalized_log_likelihood_history_)
    pred = model.predict(X_bad, groups=groups)
    assert np.all(np.isfinite(pred))
    assert model.score(X_bad, y, groups=groups) > 0.9


def test_badly_scaled_columns_give_the_same_model(data):
    X, y, groups = data
    scales = np.array([1e-4, 1e3])
    plain = HMMGMRRegressor(n_states=3, random_state=0).fit(X, y, groups=groups)
    scaled = HMMGMRRegressor(n_states=3, random_state=0).fit(X * scales, y, groups=groups)
    assert_non_decreasing(scaled.penalized_log_likelihood_history_)
    np.testing.assert_allclose(
        plain.predict(X, groups=groups), scaled.predict(X * scales, groups=groups), atol=1e-6
    )


@pytest.mark.parametrize(
    "x_factor, y_factor", [(1e-13, 1.0), (1e-100, 1.0), (1e100, 1.0), (1.0, 1e-13), (1e-13, 1e13)]
)
def test_predictions_do_not_depend_on_the_units(data, fitted, x_factor, y_factor):
    # Standardisation treats a column as constant relative to its own values, so any unit whose
    # variance float64 holds gives the same model (X * 1e-13 used to be read as constant).
    X, y, groups = data
    X_constant = np.column_stack([X, np.full(len(X), 3.7)])
    reference = HMMGMRRegressor(n_states=3, random_state=0).fit(X_constant, y, groups=groups)
    scaled = HMMGMRRegressor(n_states=3, random_state=0).fit(
        X_constant * x_factor, y * y_factor, groups=groups
    )
    expected, expected_std = reference.predict(X_constant, groups=groups, return_std=True)
    pred, std = scaled.predict(X_constant * x_factor, groups=groups, return_std=True)
    atol = 1e-8 * np.abs(expected).max()
    np.testing.assert_allclose(pred / y_factor, expected, rtol=1e-8, atol=atol)
    np.testing.assert_allclose(std / y_factor, expected_std, rtol=1e-8)


@pytest.mark.parametrize("factor, how", [(1e160, "overflow"), (1e-300, "underflow")])
def test_units_whose_variance_float64_cannot_hold_are_refused(data, factor, how):
    X, y, groups = data
    with pytest.raises(
        ValueError, match=rf"column 'x0' has standard deviation .* would {how} float64"
    ):
        HMMGMRRegressor(n_states=2).fit(X * factor, y, groups=groups)
    with pytest.raises(ValueError, match=rf"column 'output 0' .* would {how} float64"):
        HMMGMRRegressor(n_states=2).fit(X, y * factor, groups=groups)


def test_state_that_loses_its_data_stays_finite():
    rng = np.random.default_rng(0)
    X = np.concatenate([rng.normal(0, 1, size=(200, 1)), rng.normal(8, 1, size=(200, 1))])
    y = X[:, 0] * 0.5 + rng.normal(scale=0.1, size=400)
    model = HMMGMRRegressor(n_states=8, init_params="random", random_state=0, n_iter=300)
    model.fit(X, y)
    assert_non_decreasing(model.penalized_log_likelihood_history_)
    assert np.all(np.isfinite(model.means_)) and np.all(np.isfinite(model.covars_))
    assert np.all(np.isfinite(model.predict(X)))


def test_restarts_keep_the_best_objective(data):
    X, y, groups = data
    joint = np.column_stack([X, y])
    recordings = as_recordings(groups, len(joint))
    rng = np.random.RandomState(3)
    singles = [
        fit_hmm(joint, recordings, 4, n_init=1, init_params="random", random_state=rng)
        for _ in range(3)
    ]
    best = fit_hmm(
        joint, recordings, 4, n_init=3, init_params="random", random_state=np.random.RandomState(3)
    )
    # EM maximises the penalised log-likelihood: restarts are compared on it
    assert best.objective == pytest.approx(max(s.objective for s in singles), rel=1e-12)


@pytest.mark.parametrize("init_params", ["kmeans", "k-means++", "random", "random_from_data"])
def test_every_initialisation_fits(data, init_params):
    X, y, groups = data
    model = HMMGMRRegressor(n_states=3, init_params=init_params, random_state=0)
    model.fit(X, y, groups=groups)
    assert_non_decreasing(model.penalized_log_likelihood_history_)
    assert model.score(X, y, groups=groups) > 0.9


def test_same_seed_same_numbers(data):
    X, y, groups = data
    a = HMMGMRRegressor(n_states=3, random_state=7).fit(X, y, groups=groups)
    b = HMMGMRRegressor(n_states=3, random_state=7).fit(X, y, groups=groups)
    np.testing.assert_array_equal(a.means_, b.means_)
    np.testing.assert_array_equal(a.predict(X, groups=groups), b.predict(X, groups=groups))


def test_multi_output(data):
    X, y, groups = data
    Y = np.column_stack([y, -2.0 * y + 1.0])
    model = HMMGMRRegressor(n_states=3, random_state=0).fit(X, Y, groups=groups)
    pred, std = model.predict(X, groups=groups, return_std=True)
    assert pred.shape == Y.shape and std.shape == Y.shape
    # the second output is an exact affine function of the first: so are the estimates
    np.testing.assert_allclose(pred[:, 1], -2.0 * pred[:, 0] + 1.0, atol=1e-4)
    np.testing.assert_allclose(std[:, 1], 2.0 * std[:, 0], rtol=1e-3)


def test_predictive_std_is_calibrated(data, fitted):
    X, y, groups = data
    pred, std = fitted.predict(X, groups=groups, return_std=True)
    inside = np.abs(y - pred) <= 2 * std
    assert inside.mean() > 0.85


def test_fitted_attributes(data, fitted):
    X, _, _ = data
    K, D = 3, X.shape[1] + 1
    assert fitted.startprob_.shape == (K,)
    np.testing.assert_allclose(fitted.transmat_.sum(axis=1), 1.0)
    assert fitted.means_.shape == (K, D)
    assert fitted.covars_.shape == (K, D, D)
    for cov in fitted.covars_:
        np.testing.assert_allclose(cov, cov.T, atol=1e-12)
        assert np.all(np.linalg.eigvalsh(cov) > 0)
    assert fitted.n_features_in_ == 2 and fitted.n_outputs_ == 1
    assert fitted.n_iter_ >= 1 and isinstance(fitted.converged_, bool)
    assert fitted.log_likelihood_history_[-1] == pytest.approx(fitted.log_likelihood_)
    assert fitted.n_parameters() == (K - 1) + K * (K - 1) + K * D + K * D * (D + 1) // 2
    assert math.isfinite(fitted.bic(X, data[1], groups=data[2]))
