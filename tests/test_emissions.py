"""The emission models: both Gaussian families through the engine, the filter, streaming and
JSON, and a stub emission that shows the EM engine asks the emission object for everything."""

import json

import numpy as np
import pytest
from scipy.special import logsumexp
from scipy.stats import multivariate_normal
from test_portable import file_dict, load_dict

from skhmmgmr import FittedHMMGMR, HMMGMRRegressor, portable
from skhmmgmr._core._sequences import as_recordings
from skhmmgmr._hmm._em import HMMParameters, baum_welch
from skhmmgmr._hmm._emissions import (
    CovariancePrior,
    FullCovariance,
    MomentStatistics,
    TiedCovariance,
    emission_family,
)
from skhmmgmr._hmm._gaussian import weighted_moments
from skhmmgmr._hmm._kernels import UNDERFLOW

FAMILIES = {"full": FullCovariance, "tied": TiedCovariance}


def random_emissions(rng, covariance_type, n_states=3, n_dims=4):
    means = rng.normal(size=(n_states, n_dims))
    factors = rng.normal(size=(n_states, n_dims, n_dims))
    full = factors @ factors.transpose(0, 2, 1) + np.eye(n_dims)
    return FAMILIES[covariance_type](means, full if covariance_type == "full" else full[0])


def random_statistics(rng, n_states=3, n_dims=4, n_rows=200):
    X = rng.normal(size=(n_rows, n_dims)) + 0.5
    resp = rng.dirichlet(np.ones(n_states), size=n_rows)
    shift = X.mean(axis=0)
    return X, resp, MomentStatistics(*weighted_moments(resp, X, shift), shift)


def make_switching_data(n_recordings=3, length=200, seed=0):
    rng = np.random.default_rng(seed)
    X_parts, y_parts = [], []
    for _ in range(n_recordings):
        x = np.cumsum(rng.normal(scale=0.3, size=(length, 2)), axis=0)
        y = np.where(x[:, 0] > 0, 1.5 * x[:, 0] - 0.5 * x[:, 1], -x[:, 0] + 0.3 * x[:, 1])
        X_parts.append(x)
        y_parts.append(y + rng.normal(scale=0.1, size=length))
    groups = np.repeat([f"rec{r}" for r in range(n_recordings)], length)
    return np.vstack(X_parts), np.concatenate(y_parts), groups


@pytest.fixture(scope="module")
def data():
    return make_switching_data()


@pytest.fixture(scope="module", params=["full", "tied"])
def fitted(request, data):
    X, y, groups = data
    model = HMMGMRRegressor(n_states=3, covariance_type=request.param, random_state=0)
    return model.fit(X, y, groups=groups)


@pytest.mark.parametrize("covariance_type", ["full", "tied"])
def test_log_prob_and_marginal_match_scipy(covariance_type):
    rng = np.random.default_rng(0)
    emissions = random_emissions(rng, covariance_type)
    X = rng.normal(size=(50, 4)) * 2
    for dims, model in [([0, 1, 2, 3], emissions), ([1, 3], emissions.marginal([1, 3]))]:
        expected = np.column_stack(
            [
                multivariate_normal(m[dims], c[np.ix_(dims, dims)]).logpdf(X[:, dims])
                for m, c in zip(emissions.means, emissions.full_covariances, strict=True)
            ]
        )
        np.testing.assert_allclose(model.log_prob(X[:, dims]), expected, rtol=1e-12)
    assert type(emissions.marginal([1, 3])) is type(emissions)


@pytest.mark.parametrize("covariance_type", ["full", "tied"])
def test_condition_matches_plain_formulas(covariance_type):
    rng = np.random.default_rng(1)
    emissions = random_emissions(rng, covariance_type)
    gating, coef, intercept, conditional = emissions.condition(3)
    for k, (mean, cov) in enumerate(zip(emissions.means, emissions.full_covariances, strict=True)):
        gain = cov[3:, :3] @ np.linalg.inv(cov[:3, :3])
        np.testing.assert_allclose(coef[k], gain, rtol=1e-10)
        np.testing.assert_allclose(intercept[k], mean[3:] - gain @ mean[:3], rtol=1e-10)
        expected = cov[3:, 3:] - gain @ cov[:3, 3:]
        np.testing.assert_allclose(conditional[k], expected, rtol=1e-10)
    np.testing.assert_allclose(gating.means, emissions.means[:, :3])
    if covariance_type == "tied":
        # one shared slope; the intercepts differ by state
        np.testing.assert_allclose(coef, np.broadcast_to(coef[0], coef.shape), rtol=1e-12)
        assert not np.allclose(intercept, intercept[0])


@pytest.mark.parametrize("covariance_type", ["full", "tied"])
def test_rescaled_and_standardized_are_inverse(covariance_type):
    rng = np.random.default_rng(2)
    emissions = random_emissions(rng, covariance_type)
    center, scale = rng.normal(size=4), rng.uniform(0.1, 10, size=4)
    back = emissions.rescaled(center, scale).standardized(center, scale)
    np.testing.assert_allclose(back.means, emissions.means, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(back.covariances, emissions.covariances, rtol=1e-12)


@pytest.mark.parametrize("covariance_type", ["full", "tied"])
def test_map_adaptation_of_the_covariances_follows_the_plain_rule(covariance_type):
    """``S' = (scatter(mu') + r (S0 + (mu0 - mu')(mu0 - mu')^T)) / (n + r)`` per state (tied:
    the scatters of all states plus ``r S0`` over ``N + r``), ``reg_covar`` on the diagonal."""
    rng = np.random.default_rng(4)
    prior = random_emissions(rng, covariance_type)
    X, resp, statistics = random_statistics(rng)
    means = prior.means + rng.normal(scale=0.3, size=prior.means.shape)
    relevance, reg_covar = 5.0, 1e-3
    adapted = prior.map_adapted(statistics, means, relevance, reg_covar)
    scatter = [
        sum(r * np.outer(x - means[k], x - means[k]) for r, x in zip(resp[:, k], X, strict=True))
        for k in range(3)
    ]
    counts = resp.sum(axis=0)
    if covariance_type == "full":
        expected = np.array(
            [
                (scatter[k] + relevance * (s0 + np.outer(m0 - m, m0 - m))) / (counts[k] + relevance)
                for k, (s0, m0, m) in enumerate(
                    zip(prior.covariances, prior.means, means, strict=True)
                )
            ]
        )
    else:
        expected = (sum(scatter) + relevance * prior.covariances) / (counts.sum() + relevance)
    expected = expected + reg_covar * np.eye(4)
    assert type(adapted) is type(prior)
    np.testing.assert_array_equal(adapted.means, means)
    np.testing.assert_allclose(adapted.covariances, expected, rtol=1e-10)
    assert np.array_equal(adapted.covariances, np.swapaxes(adapted.covariances, -1, -2))


@pytest.mark.parametrize("covariance_type", ["full", "tied"])
def test_the_conditioning_quantities_are_those_of_the_covariances(covariance_type):
    rng = np.random.default_rng(5)
    emissions = random_emissions(rng, covariance_type)
    covariances = emissions.state_covariances()
    inverses = np.linalg.inv(covariances)
    deviations = rng.normal(size=(3, 7, 4))
    np.testing.assert_allclose(emissions.precisions(), inverses, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(
        emissions.precision_times(deviations), deviations @ inverses, rtol=1e-10, atol=1e-12
    )
    np.testing.assert_allclose(
        emissions.mahalanobis(deviations),
        np.einsum("knd,kde,kne->kn", deviations, inverses, deviations),
        rtol=1e-10,
    )
    np.testing.assert_allclose(
        emissions.half_log_det_precision(), -0.5 * np.linalg.slogdet(covariances)[1], rtol=1e-12
    )
    whitening = emissions.whitening()
    np.testing.assert_array_equal(whitening, np.triu(whitening))
    np.testing.assert_allclose(whitening @ whitening.transpose(0, 2, 1), inverses, rtol=1e-10)
    np.testing.assert_array_equal(
        emissions.state_variances(), np.diagonal(covariances, axis1=1, axis2=2)
    )


@pytest.mark.parametrize("covariance_type", ["full", "tied"])
def test_the_exchange_forms_give_the_same_model_back(covariance_type):
    rng = np.random.default_rng(6)
    emissions = random_emissions(rng, covariance_type)
    joint = emissions.portable_joint()
    assert joint["covariance_type"] == covariance_type
    assert joint["covariances"].shape == (3, 4, 4)  # every state's, whatever the family
    family = emission_family(joint["covariance_type"])
    back = family.from_state_covariances(joint["means"], joint["covariances"])
    assert type(back) is type(emissions)
    np.testing.assert_array_equal(back.covariances, emissions.covariances)
    np.testing.assert_array_equal(back.whitening(), emissions.whitening())
    covars = emissions.hmmlearn_covars()  # hmmlearn's setter takes the family's own shape
    np.testing.assert_array_equal(covars, emissions.covariances)
    assert not np.shares_memory(covars, emissions.covariances)
    moved = emissions.with_means(emissions.means + 1.0)
    assert type(moved) is type(emissions)
    np.testing.assert_array_equal(moved.covariances, emissions.covariances)
    frozen = emissions.frozen()
    assert not (frozen.means.flags.writeable or frozen.covariances.flags.writeable)
    np.testing.assert_array_equal(frozen.precisions(), emissions.precisions())


def test_a_tied_model_refuses_unequal_state_covariances():
    emissions = random_emissions(np.random.default_rng(7), "full")
    with pytest.raises(ValueError, match="must all be equal for covariance_type 'tied'"):
        TiedCovariance.from_state_covariances(emissions.means, emissions.covariances)


def plain_tied_objective(resp, X, means, covariance, prior_scale):
    """``sum_k sum_t r_tk log N(x_t; mu_k, S) - psi / 2 tr(S^-1)`` by a plain loop."""
    total = sum(
        resp[:, k] @ multivariate_normal(means[k], covariance).logpdf(X)
        for k in range(resp.shape[1])
    )
    return total - 0.5 * prior_scale * np.trace(np.linalg.inv(covariance))


def test_tied_m_step_is_the_plain_loop_maximiser():
    rng = np.random.default_rng(3)
    X = rng.normal(size=(300, 3)) + 1.0
    resp = rng.dirichlet(np.ones(3), size=300)
    shift = X.mean(axis=0)
    statistics = MomentStatistics(*weighted_moments(resp, X, shift), shift)
    previous = TiedCovariance(np.zeros((3, 3)), np.eye(3))
    prior = CovariancePrior(0.5)
    new = previous.maximize(statistics, prior)
    means = (resp.T @ X) / resp.sum(axis=0)[:, np.newaxis]
    scatter = sum(
        r * np.outer(x - means[k], x - means[k])
        for k in range(3)
        for r, x in zip(resp[:, k], X, strict=True)
    )
    np.testing.assert_allclose(new.means, means, rtol=1e-12)
    np.testing.assert_allclose(new.covariances, (scatter + 0.5 * np.eye(3)) / 300, rtol=1e-10)
    best = plain_tied_objective(resp, X, new.means, new.covariances, 0.5)
    for _ in range(10):
        step = rng.normal(scale=1e-3, size=(3, 3))
        moved = new.covariances + step @ step.T + 1e-4 * (step + step.T)
        moved_means = new.means + rng.normal(scale=1e-3, size=(3, 3))
        assert plain_tied_objective(resp, X, moved_means, moved, 0.5) < best


def test_parameter_counts():
    rng = np.random.default_rng(4)
    K, D = 3, 4
    assert random_emissions(rng, "full").n_parameters() == K * D + K * D * (D + 1) // 2
    assert random_emissions(rng, "tied").n_parameters() == K * D + D * (D + 1) // 2


@pytest.mark.parametrize("covariance_type", ["diag", "spherical"])
def test_diag_and_spherical_are_refused_with_the_reason(data, covariance_type):
    X, y, groups = data
    model = HMMGMRRegressor(n_states=2, covariance_type=covariance_type)
    with pytest.raises(ValueError, match="outputs would not depend on the inputs"):
        model.fit(X, y, groups=groups)
    with pytest.raises(ValueError, match="covariance_type must be one of"):
        emission_family("banana")


def reference_predict(model, X, groups):
    """Plain forward recursion on the input densities and GMR, in the data's units."""
    n_inputs = model.n_features_in_
    means, covs = model.means_, model.covars_
    estimates = np.empty(len(X))
    for recording in np.unique(groups):
        rows = np.flatnonzero(groups == recording)
        log_alpha = None
        for t in rows:
            x = X[t]
            log_b = np.array(
                [
                    multivariate_normal(m[:n_inputs], c[:n_inputs, :n_inputs]).logpdf(x)
                    for m, c in zip(means, covs, strict=True)
                ]
            )
            if log_alpha is None:
                log_alpha = np.log(model.startprob_) + log_b
            else:
                log_alpha = logsumexp(log_alpha[:, None] + np.log(model.transmat_), axis=0) + log_b
            log_alpha -= logsumexp(log_alpha)
            conditional = [
                m[n_inputs]
                + c[n_inputs, :n_inputs]
                @ np.linalg.solve(c[:n_inputs, :n_inputs], x - m[:n_inputs])
                for m, c in zip(means, covs, strict=True)
            ]
            estimates[t] = np.exp(log_alpha) @ np.asarray(conditional)
    return estimates


def test_fit_filter_stream_and_json_agree_for_both_families(data, fitted, tmp_path):
    X, y, groups = data
    history = fitted.penalized_log_likelihood_history_
    assert np.max(-np.diff(history)) <= 1e-9 * np.abs(history).max()
    predicted = fitted.predict(X, groups=groups)
    np.testing.assert_allclose(predicted, reference_predict(fitted, X, groups), atol=1e-9)
    # the two regimes differ in slope: tied states share one slope, so fit them less well
    assert fitted.score(X, y, groups=groups) > (0.9 if fitted.covariance_type == "full" else 0.75)
    first = groups == groups[0]
    streamed = fitted.filter_stream().update_batch(X[first])
    np.testing.assert_allclose(streamed, predicted[first], rtol=0, atol=1e-12)
    path = tmp_path / "model.json"
    portable.save(fitted, path)
    assert json.loads(path.read_text())["joint"]["covariance_type"] == fitted.covariance_type
    restored = portable.load(path)
    assert restored.covariance_type == fitted.covariance_type
    np.testing.assert_array_equal(restored.predict(X, groups=groups), predicted)
    if fitted.covariance_type == "tied":
        np.testing.assert_allclose(fitted.covars_, np.broadcast_to(fitted.covars_[0], (3, 3, 3)))


def test_adapted_models_of_both_families_export_and_stream_exactly(data, fitted, tmp_path):
    """Adaptation (means, covariances, transitions, batch and online) keeps the family, and
    the adapted models go through JSON and hmmlearn and back bit for bit."""
    from skhmmgmr._hmm._hmmlearn import from_hmmlearn

    X, y, groups = data
    first = groups == groups[0]
    adapted = HMMGMRRegressor.from_fitted_model(fitted.model_, **fitted.get_params())
    adapted.adapt(X[first], y[first] + 0.5, relevance=4.0, parameters="mvt")
    assert adapted.covariance_type == fitted.covariance_type
    assert not np.allclose(adapted.covars_, fitted.covars_)
    predicted = adapted.predict(X, groups=groups)
    restored = load_dict(file_dict(adapted, tmp_path), tmp_path)
    np.testing.assert_array_equal(restored.predict(X, groups=groups), predicted)
    np.testing.assert_array_equal(restored.covars_, adapted.covars_)
    back = from_hmmlearn(adapted.to_hmmlearn())
    np.testing.assert_array_equal(back.data_emissions.means, adapted.means_)
    np.testing.assert_array_equal(back.data_emissions.state_covariances(), adapted.covars_)
    stream = fitted.filter_stream(relevance=8.0)
    for row, target in zip(X[first][:50], y[first][:50], strict=True):
        stream.update(row, target=target)
    online = stream.adapted_model()
    assert online.covariance_type == fitted.covariance_type
    np.testing.assert_allclose(
        online.emissions.covariances, fitted.model_.emissions.covariances, rtol=1e-14
    )
    assert not np.allclose(online.emissions.means, fitted.model_.emissions.means)


def test_a_tied_file_with_unequal_covariances_is_refused(data, tmp_path):
    X, y, groups = data
    model = HMMGMRRegressor(n_states=2, covariance_type="tied", random_state=0)
    data_dict = file_dict(model.fit(X, y, groups=groups), tmp_path)
    data_dict["joint"]["covariances"][1][0][0] *= 2.0
    with pytest.raises(ValueError, match="must all be equal"):
        load_dict(data_dict, tmp_path)


def test_fitted_model_is_immutable(fitted):
    model = fitted.model_
    assert isinstance(model, FittedHMMGMR)
    with pytest.raises(AttributeError):
        model.startprob = np.ones(3) / 3
    for array in (
        model.startprob,
        model.transmat,
        model.emissions.means,
        model.data_emissions.means,
    ):
        with pytest.raises(ValueError, match="read-only"):
            array[0] = 0.0


class UnitGaussians:
    """Stub emission: Gaussians with identity covariance, means only (as hmmlearn tests its
    base class with a small emission of its own)."""

    covariance_type = "unit"

    def __init__(self, means):
        self.means = np.asarray(means, dtype=float)

    @property
    def n_states(self):
        return self.means.shape[0]

    @classmethod
    def prior_for(cls, reg_covar, n_samples, n_states):
        return None

    def log_prior(self, prior):
        return 0.0

    def density(self, shift):
        means = self.means - shift

        class Density:
            def frames(self, columns, frames, top):
                X = columns[:-1].T
                log_b = -0.5 * ((X[:, None, :] - means) ** 2).sum(axis=2)
                log_b -= 0.5 * means.shape[1] * np.log(2 * np.pi)
                top[:] = log_b.max(axis=1)
                difference = log_b - top[:, None]
                frames[:] = np.where(difference < UNDERFLOW, 0.0, np.exp(difference))

        return Density()

    def maximize(self, statistics, prior):
        return UnitGaussians(statistics.shift + statistics.first / statistics.weights[:, None])


def plain_unit_em(X, bounds, startprob, transmat, means, n_iter):
    """Log-space Baum-Welch for identity-covariance Gaussians, recording by recording."""
    history = []
    for _ in range(n_iter):
        log_b = -0.5 * ((X[:, None, :] - means) ** 2).sum(axis=2) - X.shape[1] / 2 * np.log(
            2 * np.pi
        )
        gamma, xi, starts, total = np.zeros_like(log_b), 0.0, 0.0, 0.0
        for lo, hi in zip(bounds[:-1], bounds[1:], strict=True):
            n = hi - lo
            la, lb = np.empty((n, len(startprob))), np.zeros((n, len(startprob)))
            la[0] = np.log(startprob) + log_b[lo]
            for t in range(1, n):
                la[t] = logsumexp(la[t - 1][:, None] + np.log(transmat), axis=0) + log_b[lo + t]
            for t in range(n - 2, -1, -1):
                lb[t] = logsumexp(np.log(transmat) + log_b[lo + t + 1] + lb[t + 1], axis=1)
            log_p = logsumexp(la[-1])
            total += log_p
            gamma[lo:hi] = np.exp(la + lb - log_p)
            starts = starts + gamma[lo]
            pairs = la[:-1, :, None] + np.log(transmat) + (log_b[lo + 1 : hi] + lb[1:])[:, None]
            xi = xi + np.exp(pairs - log_p).sum(axis=0)
        history.append(total)
        startprob = starts / starts.sum()
        transmat = xi / xi.sum(axis=1, keepdims=True)
        means = (gamma.T @ X) / gamma.sum(axis=0)[:, None]
    return history, means


def test_engine_runs_a_stub_emission_like_a_plain_loop():
    rng = np.random.default_rng(5)
    X = np.vstack([rng.normal(-2, 1, size=(120, 2)), rng.normal(2, 1, size=(130, 2))])
    X = X[rng.permutation(250)]
    groups = np.repeat([0, 1, 2], [100, 90, 60])
    recordings = as_recordings(groups, len(X))
    startprob, transmat = np.array([0.6, 0.4]), np.array([[0.7, 0.3], [0.2, 0.8]])
    means = np.array([[-1.0, -1.0], [1.0, 0.5]])
    start = HMMParameters(startprob, transmat, UnitGaussians(means))
    result = baum_welch(X, recordings, start, n_iter=6, tol=0.0, reg_covar=0.0)
    expected_history, expected_means = plain_unit_em(
        X, np.array([0, 100, 190, 250]), startprob, transmat, means, 6
    )
    np.testing.assert_allclose(result.history[:6], expected_history, rtol=1e-11)
    np.testing.assert_allclose(result.parameters.emissions.means, expected_means, rtol=1e-10)
