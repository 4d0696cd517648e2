"""MAP adaptation (``adapt``), forecasts ahead (``predict_ahead``) and ``shift_target``."""

import pickle

import numpy as np
import pandas as pd
import pytest
from scipy.stats import multivariate_normal
from test_portable import file_dict, load_dict

from skhmmgmr import HMMGMRRegressor
from skhmmgmr._core._sequences import as_recordings
from skhmmgmr._hmm._em import baum_welch
from skhmmgmr.datasets import shift_target


def _data(n_samples, seed, offset=0.0):
    rng = np.random.default_rng(seed)
    X = np.cumsum(rng.normal(size=(n_samples, 2)), axis=0) / 10
    y = 2.0 * X[:, 0] - X[:, 1] + offset + rng.normal(scale=0.1, size=n_samples)
    return X, y


@pytest.fixture(scope="module")
def fitted():
    X, y = _data(600, 0)
    # tol=0: every MAP iteration runs, as in the plain EM it is compared with.
    return HMMGMRRegressor(n_states=2, random_state=0).fit(X, y).set_params(tol=0.0)


def _copy(model):
    return pickle.loads(pickle.dumps(model))


def test_adapt_with_no_rows_leaves_the_model_unchanged(fitted):
    model = _copy(fitted)
    before = model.model_
    X, y = _data(10, 1)
    assert model.adapt(X[:0], y[:0], parameters="mvt") is model
    assert model.model_ is before
    assert np.array_equal(model.predict(X), fitted.predict(X))


def test_adapt_builds_a_new_model_and_keeps_what_is_not_adapted(fitted):
    model = _copy(fitted)
    before = model.model_
    X, y = _data(300, 2, offset=0.5)
    model.adapt(X, y, relevance=16.0, parameters="m", n_iter=3)
    assert model.model_ is not before
    assert model.model_.standardization is before.standardization
    assert np.array_equal(model.transmat_, before.transmat)
    np.testing.assert_allclose(model.covars_, fitted.covars_, rtol=1e-12, atol=1e-14)
    assert not np.allclose(model.means_, fitted.means_)
    # The adapted model predicts the shifted target better.
    assert model.score(X, y) > fitted.score(X, y)


def test_a_large_relevance_keeps_the_fitted_model(fitted):
    model = _copy(fitted)
    X, y = _data(200, 3, offset=0.5)
    model.adapt(X, y, relevance=1e12, parameters="mvt", n_iter=2)
    np.testing.assert_allclose(model.means_, fitted.means_, rtol=0, atol=1e-6)
    np.testing.assert_allclose(model.transmat_, fitted.transmat_, rtol=0, atol=1e-9)


def _plain_em(fitted, X, y, groups, n_iter):
    scaling = fitted.model_.standardization
    joint = scaling.joint(X, y.reshape(-1, 1))
    result = baum_welch(
        joint,
        as_recordings(groups, X.shape[0]),
        fitted.model_.hmm_parameters(),
        n_iter=n_iter,
        tol=0.0,
        reg_covar=0.0,
    )
    return result.parameters


def test_with_many_rows_adaptation_approaches_plain_em_from_the_fitted_model(fitted):
    gaps = []
    for n_recordings in (1, 40):
        # Recordings like the training ones, so that every state is visited.
        parts = [_data(600, 100 + i, offset=0.3) for i in range(n_recordings)]
        X, y = np.vstack([p[0] for p in parts]), np.concatenate([p[1] for p in parts])
        groups = np.repeat(np.arange(n_recordings), 600)
        model = _copy(fitted).adapt(X, y, groups, relevance=16.0, parameters="mvt", n_iter=3)
        reference = _plain_em(fitted, X, y, groups, n_iter=3)
        adapted = model.model_
        pairs = [
            (adapted.emissions.means, reference.means),
            (adapted.emissions.full_covariances, reference.covariances),
            (adapted.transmat, reference.transmat),
        ]
        gaps.append(max(np.max(np.abs(a - b)) / np.max(np.abs(b)) for a, b in pairs))
    assert gaps[1] < gaps[0] / 5
    assert gaps[1] < 1e-2


def test_adapted_models_round_trip_through_json_and_pickle(fitted, tmp_path):
    X, y = _data(300, 6, offset=0.5)
    model = _copy(fitted).adapt(X, y, parameters="mvt", n_iter=2)
    restored = load_dict(file_dict(model, tmp_path), tmp_path)
    assert np.array_equal(restored.predict(X), model.predict(X))
    assert np.array_equal(_copy(model).predict(X), model.predict(X))


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"parameters": "mx"}, "parameters"),
        ({"relevance": -1e-9}, "relevance"),
        ({"relevance": 0.0, "parameters": "mv"}, "parameters"),
        ({"n_iter": 0}, "n_iter"),
    ],
)
def test_adapt_refuses_bad_arguments(fitted, kwargs, match):
    X, y = _data(50, 7)
    with pytest.raises(ValueError, match=match):
        _copy(fitted).adapt(X, y, **kwargs)


def _reference_ahead(model, X, groups, steps, state_output):
    """Plain loops in the data's units: filter, propagate, mix."""
    means, covars = model.means_, model.covars_
    n_in = X.shape[1]
    transmat, startprob = model.transmat_, model.startprob_
    out = np.empty(X.shape[0])
    previous = None
    for t in range(X.shape[0]):
        density = np.array(
            [
                multivariate_normal(means[k, :n_in], covars[k, :n_in, :n_in]).pdf(X[t])
                for k in range(len(startprob))
            ]
        )
        start = t == 0 or groups[t] != groups[t - 1]
        prior = startprob if start else previous @ transmat
        alpha = prior * density
        alpha /= alpha.sum()
        previous = alpha
        ahead = alpha.copy()
        for _ in range(steps):
            ahead = ahead @ transmat
        value = 0.0
        for k in range(len(startprob)):
            mean = means[k, n_in]
            if steps == 0 or state_output == "conditional":
                s_ff, s_tf = covars[k, :n_in, :n_in], covars[k, n_in, :n_in]
                mean = mean + s_tf @ np.linalg.solve(s_ff, X[t] - means[k, :n_in])
            value += ahead[k] * mean
        out[t] = value
    return out


@pytest.mark.parametrize("state_output", ["marginal", "conditional"])
@pytest.mark.parametrize("steps", [0, 1, 7])
def test_predict_ahead_matches_a_plain_loop(fitted, state_output, steps):
    X, _ = _data(40, 8)
    groups = np.repeat(["a", "b"], 20)
    got = fitted.predict_ahead(X, steps, groups=groups, state_output=state_output)
    expected = _reference_ahead(fitted, X, groups, steps, state_output)
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-10)


def test_predict_ahead_at_zero_steps_is_predict_and_the_std_is_returned(fitted):
    X, _ = _data(60, 9)
    estimate, std = fitted.predict(X, return_std=True)
    got, got_std = fitted.predict_ahead(X, 0, return_std=True)
    np.testing.assert_allclose(got, estimate, rtol=0, atol=1e-12)
    np.testing.assert_allclose(got_std, std, rtol=0, atol=1e-12)
    _, far_std = fitted.predict_ahead(X, 10, return_std=True)
    assert far_std.shape == (60,) and np.all(far_std > 0)
    with pytest.raises(ValueError, match="state_output"):
        fitted.predict_ahead(X, 1, state_output="other")
    with pytest.raises(ValueError, match="steps"):
        fitted.predict_ahead(X, -1)


def test_transition_power_equals_a_plain_loop_and_stays_stochastic():
    from skhmmgmr.estimator._adaptation import transition_power

    rng = np.random.default_rng(0)
    transmat = rng.dirichlet(np.ones(4), size=4)
    loop = np.eye(4)
    for steps in range(40):
        np.testing.assert_allclose(transition_power(transmat, steps), loop, rtol=0, atol=1e-14)
        loop = loop @ transmat
    # far past the mixing time: every row is the stationary distribution pi (pi A = pi)
    values, vectors = np.linalg.eig(transmat.T)
    pi = np.real(vectors[:, np.argmin(np.abs(values - 1.0))])
    pi /= pi.sum()
    far = transition_power(transmat, 10**9)
    np.testing.assert_allclose(far, np.tile(pi, (4, 1)), rtol=0, atol=1e-12)
    assert np.all(far >= 0) and np.allclose(far.sum(axis=1), 1.0, rtol=0, atol=1e-15)


def test_a_far_horizon_forecasts_the_stationary_mixture_of_the_state_means(fitted):
    """#35: steps=10**17 returned -1148 where every state mean lay in [-5.7, -1.5]."""
    X, _ = _data(30, 10)
    model = fitted.model_
    far = fitted.predict_ahead(X, 10**9)
    values, vectors = np.linalg.eig(model.transmat.T)
    pi = np.real(vectors[:, np.argmin(np.abs(values - 1.0))])
    pi /= pi.sum()
    means = model.standardization.outputs(model.emissions.means[:, model.n_inputs :])[:, 0]
    np.testing.assert_allclose(far, pi @ means, rtol=0, atol=1e-9)
    assert means.min() <= far.min() and far.max() <= means.max()


@pytest.mark.parametrize("steps", [10**17, 10**9 + 1, True, np.inf, np.nan, None, "3", -1, 2.5])
def test_a_horizon_that_is_not_a_number_of_rows_is_named(fitted, steps):
    X, _ = _data(10, 11)
    with pytest.raises(ValueError, match=r"The .steps. parameter of predict_ahead must be an int"):
        fitted.predict_ahead(X, steps)


def test_shift_target_never_crosses_a_recording():
    y = np.arange(7.0)
    got = shift_target(y, 2, groups=list("aaabbbb"))
    np.testing.assert_array_equal(got, [2.0, np.nan, np.nan, 5.0, 6.0, np.nan, np.nan])
    np.testing.assert_array_equal(shift_target(y, 0), y)
    assert np.isnan(shift_target(y, 9)).all()
    two = shift_target(np.column_stack([y, -y]), 1)
    np.testing.assert_array_equal(two[:-1, 1], -y[1:])
    with pytest.raises(ValueError, match="horizon_rows"):
        shift_target(y, -1)


def test_shift_target_reads_a_panel_index_in_any_row_order():
    index = pd.MultiIndex.from_arrays(
        [list("bababa"), [0, 0, 1, 1, 2, 2]], names=["recording", "time"]
    )
    y = pd.Series([10.0, 0.0, 11.0, 1.0, 12.0, 2.0], index=index, name="torque")
    got = shift_target(y, 1)
    assert got.index.equals(index) and got.name == "torque"
    np.testing.assert_array_equal(got.to_numpy(), [11.0, 1.0, 12.0, 2.0, np.nan, np.nan])


# --- #35: what adapt refuses, and what it now does with a tiny relevance ---------------------


def test_adapt_refuses_rows_of_y_or_groups_without_rows_of_x(fitted):
    X, y = _data(400, 12)
    groups = np.repeat(["a", "b"], 200)
    with pytest.raises(ValueError, match="X has no rows but y has 400, groups has 400"):
        _copy(fitted).adapt(X[:0], y, groups=groups)
    with pytest.raises(ValueError, match="X has no rows but y has 400"):
        _copy(fitted).adapt(X[:0], y)


@pytest.mark.parametrize(
    "options, parameter",
    [
        ({"relevance": "16"}, "relevance"),
        ({"relevance": True}, "relevance"),
        ({"relevance": -1.0}, "relevance"),
        ({"relevance": -np.inf}, "relevance"),
        ({"relevance": np.nan}, "relevance"),
        ({"relevance": "Auto"}, "relevance"),
        ({"relevance": None}, "relevance"),
        ({"parameters": "auto "}, "parameters"),
        ({"parameters": None}, "parameters"),
        ({"parameters": ["m", "v"]}, "parameters"),
        ({"n_iter": None}, "n_iter"),
        ({"n_iter": np.inf}, "n_iter"),
        ({"n_iter": 2.5}, "n_iter"),
        ({"n_iter": True}, "n_iter"),
    ],
)
def test_adapt_names_a_parameter_out_of_its_range(fitted, options, parameter):
    X, y = _data(50, 13)
    with pytest.raises(ValueError, match=rf"The '{parameter}' parameter of adapt must be"):
        _copy(fitted).adapt(X, y, **options)


def test_a_tiny_relevance_adapts_covariances_as_fit_regularises_them(fitted):
    """#35: relevance=1e-300 with covariances raised "increase reg_covar", a parameter adapt
    does not have; adapt now adds the estimator's reg_covar in its M-step, as fit does."""
    X, y = _data(10, 14)
    model = _copy(fitted).adapt(X, y, relevance=1e-300, parameters="mvt", n_iter=2)
    eigenvalues = np.linalg.eigvalsh(model.model_.emissions.full_covariances)
    assert np.all(eigenvalues >= 0.99 * fitted.reg_covar)
    assert np.isfinite(model.predict(X)).all()
    # without any regularisation the failure names adapt's own remedies
    bare = _copy(fitted).set_params(reg_covar=0.0)
    with pytest.raises(ValueError, match=r"adapt: .*relevance=1e-300.*raise relevance"):
        bare.adapt(X, y, relevance=1e-300, parameters="mvt", n_iter=2)


def test_score_names_a_missing_target():
    """#35: a NaN target said only "Input contains NaN.", although X may hold NaN."""
    X, y = _data(200, 15)
    model = HMMGMRRegressor(n_states=2, random_state=0, missing_values="marginalize").fit(X, y)
    y = pd.Series(y, name="torque")
    y.iloc[17] = np.nan
    with pytest.raises(ValueError, match=r"Input y contains NaN in column 'torque'.*row 17"):
        model.score(X, y)


def test_the_defaults_choose_the_strength_and_adapt_with_the_choice(fitted):
    """#48: relevance and parameters default to "auto"; the chosen pair then adapts."""
    X, y = _data(300, 5, offset=0.5)
    default = _copy(fitted).adapt(X, y, n_iter=3)
    chosen = default.adaptation_[default.adaptation_["chosen"]].iloc[0]
    relevance, parameters = chosen["relevance"], chosen["parameters"]
    assert relevance < np.inf  # an offset of 0.5 is far
    explicit = _copy(fitted).adapt(X, y, relevance=relevance, parameters=parameters, n_iter=3)
    assert explicit.adaptation_ is None
    assert np.array_equal(default.predict(X), explicit.predict(X))
    assert np.array_equal(default.covars_, explicit.covars_)
