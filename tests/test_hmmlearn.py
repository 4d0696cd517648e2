"""hmmlearn with a real role: our models as ``GaussianHMM`` and hmmlearn's models read out by
our causal GMR, with the same log-likelihood and the same predictions on both sides."""

import warnings

import numpy as np
import pandas as pd
import pytest
from hmmlearn.hmm import GaussianHMM
from test_emissions import make_switching_data, reference_predict

from skhmmgmr import HMMGMRRegressor


@pytest.fixture(scope="module")
def data():
    return make_switching_data(seed=1)


def lengths_of(groups):
    _, first, counts = np.unique(groups, return_index=True, return_counts=True)
    return counts[np.argsort(first)]


@pytest.mark.parametrize("covariance_type", ["full", "tied"])
def test_our_model_as_hmmlearn_scores_and_predicts_the_same(data, covariance_type):
    X, y, groups = data
    model = HMMGMRRegressor(n_states=3, covariance_type=covariance_type, random_state=0)
    model.fit(X, y, groups=groups)
    hmm = model.to_hmmlearn()
    assert isinstance(hmm, GaussianHMM) and hmm.covariance_type == covariance_type
    joint = np.column_stack([X, y])
    expected = model.log_likelihood(X, y, groups=groups)
    assert hmm.score(joint, lengths=lengths_of(groups)) == pytest.approx(expected, rel=1e-10)
    back = HMMGMRRegressor.from_hmmlearn(hmm, n_outputs=1)
    assert back.covariance_type == covariance_type
    np.testing.assert_allclose(
        back.predict(X, groups=groups), model.predict(X, groups=groups), rtol=1e-10, atol=1e-10
    )
    assert back.log_likelihood(X, y, groups=groups) == pytest.approx(expected, rel=1e-10)
    # hmmlearn's own tools work on the converted model
    states = hmm.predict(joint, lengths=lengths_of(groups))
    assert states.shape == (len(X),) and set(states) <= {0, 1, 2}


@pytest.mark.parametrize("covariance_type", ["full", "tied"])
def test_a_model_trained_by_hmmlearn_is_read_out_by_causal_gmr(data, covariance_type):
    X, y, groups = data
    joint = np.column_stack([X, y])
    hmm = GaussianHMM(n_components=3, covariance_type=covariance_type, random_state=0, n_iter=30)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        hmm.fit(joint, lengths=lengths_of(groups))
    model = HMMGMRRegressor.from_hmmlearn(hmm, n_outputs=1, feature_names=["a", "b"])
    named = pd.DataFrame(X, columns=["a", "b"])
    expected = hmm.score(joint, lengths=lengths_of(groups))
    assert model.log_likelihood(named, y, groups=groups) == pytest.approx(expected, rel=1e-10)
    np.testing.assert_allclose(
        model.predict(named, groups=groups), reference_predict(model, X, groups), atol=1e-9
    )
    np.testing.assert_array_equal(model.feature_names_in_, ["a", "b"])
    np.testing.assert_allclose(model.means_, hmm.means_, rtol=1e-12)


def test_multi_output_conversion(data):
    X, y, groups = data
    Y = np.column_stack([y, 0.5 * y + X[:, 0]])
    model = HMMGMRRegressor(n_states=2, random_state=0).fit(X, Y, groups=groups)
    back = HMMGMRRegressor.from_hmmlearn(model.to_hmmlearn(), n_outputs=2)
    prediction = back.predict(X, groups=groups)
    assert prediction.shape == Y.shape
    np.testing.assert_allclose(prediction, model.predict(X, groups=groups), atol=1e-10)


def test_conversion_errors_say_what_is_wrong(data):
    X, y, groups = data
    with pytest.raises(ValueError, match="not fitted"):
        HMMGMRRegressor.from_hmmlearn(GaussianHMM(n_components=2))
    diag = GaussianHMM(n_components=2, covariance_type="diag", random_state=0, n_iter=3)
    diag.fit(np.column_stack([X, y]))
    with pytest.raises(ValueError, match="outputs would not depend on the inputs"):
        HMMGMRRegressor.from_hmmlearn(diag)
    hmm = HMMGMRRegressor(n_states=2, random_state=0).fit(X, y, groups=groups).to_hmmlearn()
    with pytest.raises(ValueError, match="n_outputs must be an integer in"):
        HMMGMRRegressor.from_hmmlearn(hmm, n_outputs=3)


def _first_order(estimates, groups, decay):
    """The read-out by a plain loop: s_t = a s_(t-1) + (1 - a) e_t, restarted per recording."""
    smoothed = np.array(estimates, dtype=float)
    for t in range(1, len(smoothed)):
        if groups[t] == groups[t - 1]:
            smoothed[t] = decay * smoothed[t - 1] + (1 - decay) * smoothed[t]
    return smoothed


def test_output_smoothing_given_to_from_hmmlearn_smooths_the_predictions(data, tmp_path):
    """#51 item 6: output_smoothing=5.0 was stored by get_params, ignored by predict and kept
    in the saved file."""
    from skhmmgmr import portable

    X, y, groups = data
    hmm = HMMGMRRegressor(n_states=3, random_state=0).fit(X, y, groups=groups).to_hmmlearn()
    plain = HMMGMRRegressor.from_hmmlearn(hmm, n_outputs=1)
    smoothed = HMMGMRRegressor.from_hmmlearn(hmm, n_outputs=1, output_smoothing=5.0)
    assert smoothed.get_params()["output_smoothing"] == 5.0
    assert smoothed.output_smoothing_ == pytest.approx(5.0, rel=1e-12)
    expected = _first_order(plain.predict(X, groups=groups), groups, np.exp(-1 / 5.0))
    got = smoothed.predict(X, groups=groups)
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-12)
    assert not np.allclose(got, plain.predict(X, groups=groups))
    # the saved file holds the read-out, and loads predicting the same
    path = tmp_path / "smoothed.json"
    portable.save(smoothed, path)
    restored = portable.load(path)
    np.testing.assert_array_equal(restored.predict(X, groups=groups), got)
    with pytest.raises(ValueError, match="output_smoothing='auto': 'auto' chooses the read-out"):
        HMMGMRRegressor.from_hmmlearn(hmm, n_outputs=1, output_smoothing="auto")


def test_from_fitted_model_applies_or_refuses_output_smoothing(data):
    X, y, groups = data
    fitted = HMMGMRRegressor(n_states=2, output_smoothing=3.0, random_state=0)
    fitted.fit(X, y, groups=groups)
    expected = fitted.predict(X, groups=groups)
    # the model's own read-out is kept without the parameter, or with the same time constant
    for params in ({}, {"output_smoothing": 3.0}, {"output_smoothing": "auto"}):
        copy = HMMGMRRegressor.from_fitted_model(fitted.model_, **params)
        np.testing.assert_array_equal(copy.predict(X, groups=groups), expected)
    for other in (5.0, 0.0):
        with pytest.raises(ValueError, match=rf"output_smoothing={other!r} asks for a read-out"):
            HMMGMRRegressor.from_fitted_model(fitted.model_, output_smoothing=other)
    # a model without a read-out is given the one asked for
    bare = fitted.model_.with_output_decay(np.zeros(1))
    copy = HMMGMRRegressor.from_fitted_model(bare, output_smoothing=3.0)
    np.testing.assert_allclose(copy.predict(X, groups=groups), expected, rtol=0, atol=1e-12)
