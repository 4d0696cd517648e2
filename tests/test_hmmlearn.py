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
