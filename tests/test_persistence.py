"""clone, parameters, pandas in and out, pickling, joblib and skops round-trips."""

import pickle

import joblib
import numpy as np
import pandas as pd
import pytest
from sklearn.base import clone
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import StandardScaler

from skhmmgmr import HMMGMRRegressor


@pytest.fixture(scope="module")
def frame():
    rng = np.random.default_rng(1)
    n = 300
    X = pd.DataFrame(
        {
            "steering_wheel_angle": np.cumsum(rng.normal(size=n)) / 10,
            "yaw_rate": np.cumsum(rng.normal(size=n)) / 50,
            "road_curvature_10m": rng.normal(size=n) / 1000,
        }
    )
    y = pd.Series(
        np.tanh(X["steering_wheel_angle"]) + 3 * X["yaw_rate"] + rng.normal(scale=0.05, size=n)
    )
    groups = np.repeat(["a", "b", "c"], 100)
    return X, y, groups


@pytest.fixture(scope="module")
def fitted(frame):
    X, y, groups = frame
    return HMMGMRRegressor(n_states=3, random_state=0).fit(X, y, groups=groups)


def test_init_stores_parameters_verbatim():
    model = HMMGMRRegressor(7, n_iter=3, tol=0.5, n_init=2, reg_covar=1e-3, random_state=4)
    assert model.get_params() == {
        "n_states": 7,
        "covariance_type": "full",
        "n_iter": 3,
        "tol": 0.5,
        "n_init": 2,
        "init_params": "kmeans",
        "reg_covar": 1e-3,
        "missing_values": "error",
        "output_smoothing": None,
        "min_log_density": None,
        "random_state": 4,
        "verbose": 0,
    }
    assert model.set_params(n_states=2).n_states == 2


def test_clone_is_unfitted_with_same_params(fitted):
    copy = clone(fitted)
    assert copy.get_params() == fitted.get_params()
    assert not hasattr(copy, "means_")


def test_dataframe_input_records_feature_names(fitted, frame):
    X, _, _ = frame
    np.testing.assert_array_equal(fitted.feature_names_in_, X.columns)


def test_set_output_pandas_for_state_probabilities(frame):
    X, y, groups = frame
    model = HMMGMRRegressor(n_states=3, random_state=0).set_output(transform="pandas")
    proba = model.fit(X, y, groups=groups).transform(X, groups=groups)
    assert isinstance(proba, pd.DataFrame)
    assert list(proba.columns) == ["state_0", "state_1", "state_2"]
    np.testing.assert_allclose(proba.sum(axis=1), 1.0)
    np.testing.assert_allclose(proba.to_numpy(), model.predict_state_proba(X, groups=groups))
    fit_transformed = clone(model).fit_transform(X, y, groups=groups)
    np.testing.assert_allclose(fit_transformed.to_numpy(), proba.to_numpy())


def test_pandas_pipeline_end_to_end(frame):
    X, y, groups = frame
    pipe = make_pipeline(StandardScaler(), HMMGMRRegressor(n_states=3, random_state=0))
    pipe.set_output(transform="pandas")
    pipe.fit(X, y, hmmgmrregressor__groups=groups)
    np.testing.assert_array_equal(pipe[-1].feature_names_in_, X.columns)
    pred = pipe.predict(X, groups=groups)
    assert pred.shape == (len(X),)
    assert pipe.score(X, y, groups=groups) > 0.9


def _assert_same_model(a, b, X, groups):
    np.testing.assert_array_equal(a.predict(X, groups=groups), b.predict(X, groups=groups))
    np.testing.assert_array_equal(a.means_, b.means_)


def test_pickle_round_trip(fitted, frame):
    X, _, groups = frame
    _assert_same_model(fitted, pickle.loads(pickle.dumps(fitted)), X, groups)


def test_joblib_round_trip(fitted, frame, tmp_path):
    X, _, groups = frame
    path = tmp_path / "model.joblib"
    joblib.dump(fitted, path)
    _assert_same_model(fitted, joblib.load(path), X, groups)


def test_skops_round_trip_with_trusted_types(fitted, frame, tmp_path):
    sio = pytest.importorskip("skops.io")
    X, _, groups = frame
    path = tmp_path / "model.skops"
    sio.dump(fitted, path)
    untrusted = sio.get_untrusted_types(file=path)
    # the estimator and the parts of its fitted model, nothing from outside the package
    assert "skhmmgmr.estimator.HMMGMRRegressor" in untrusted
    assert "skhmmgmr.FittedHMMGMR" in untrusted
    assert all(name.startswith("skhmmgmr.") for name in untrusted), untrusted
    loaded = sio.load(path, trusted=untrusted)
    _assert_same_model(fitted, loaded, X, groups)
