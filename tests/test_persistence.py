"""clone, parameters, pandas in and out, pickling, joblib and skops round-trips, and the
version every pickle carries."""

import pickle
import warnings

import joblib
import numpy as np
import pandas as pd
import pytest
from sklearn.base import clone
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import StandardScaler

import skhmmgmr
from skhmmgmr import HMMGMRRegressor, InconsistentVersionWarning
from skhmmgmr._core._pickled import PickleVersionMixin


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
    # the estimator and the parts of its fitted model, by the modules that define them,
    # nothing from outside the package
    assert "skhmmgmr.estimator._regressor.HMMGMRRegressor" in untrusted
    assert "skhmmgmr._hmm._fitted.FittedHMMGMR" in untrusted
    assert all(name.startswith("skhmmgmr.") for name in untrusted), untrusted
    with warnings.catch_warnings():
        warnings.simplefilter("error", InconsistentVersionWarning)
        loaded = sio.load(path, trusted=untrusted)
    _assert_same_model(fitted, loaded, X, groups)


def _pickled_by(obj, version):
    """``obj`` pickled as skhmmgmr ``version`` would (the version the mixin records)."""
    from unittest import mock

    from skhmmgmr._core import _pickled

    with mock.patch.object(_pickled, "__version__", version):
        return pickle.dumps(obj)


def test_a_pickle_carries_the_version_and_loads_silently_by_the_same(fitted):
    """As scikit-learn's ``_sklearn_version``: the state holds the skhmmgmr that wrote it."""
    assert fitted.__getstate__()["_skhmmgmr_version"] == skhmmgmr.__version__
    assert fitted.model_.__getstate__()["_skhmmgmr_version"] == skhmmgmr.__version__
    assert "_skhmmgmr_version" not in vars(pickle.loads(pickle.dumps(fitted)))
    with warnings.catch_warnings():
        warnings.simplefilter("error", InconsistentVersionWarning)
        pickle.loads(pickle.dumps(fitted))
        pickle.loads(pickle.dumps(fitted.filter_stream()))


@pytest.mark.parametrize("what", ["regressor", "stream"])
def test_a_pickle_of_another_version_warns_naming_both_versions(fitted, frame, what):
    X, _, groups = frame
    obj = fitted if what == "regressor" else fitted.filter_stream()
    data = _pickled_by(obj, "0.0.7")
    with pytest.warns(InconsistentVersionWarning) as caught:
        loaded = pickle.loads(data)
    messages = {record.message.class_name: str(record.message) for record in caught}
    expected = {"HMMGMRRegressor", "FittedHMMGMR"} if what == "regressor" else {"FilterStream"}
    assert expected <= set(messages)
    for message in messages.values():
        assert "skhmmgmr 0.0.7" in message and f"skhmmgmr {skhmmgmr.__version__}" in message
    assert caught[0].message.original_version == "0.0.7"
    assert caught[0].message.current_version == skhmmgmr.__version__
    # it still loads: a warning, not a refusal
    if what == "regressor":
        _assert_same_model(fitted, loaded, X, groups)


def _public_classes():
    import inspect
    from importlib import import_module

    modules = ["skhmmgmr", "skhmmgmr.metrics", "skhmmgmr.streaming", "skhmmgmr.torque_pipeline"]
    found = {}
    for name in modules:
        module = import_module(name)
        for value in map(module.__dict__.get, module.__all__):
            if inspect.isclass(value) and not issubclass(value, Warning):
                found[value.__name__] = value
    return found


# Classes users do not pickle on their own: parts of a fitted model pickled inside it, and
# descriptions of settings.
NOT_PICKLED_ALONE = {"Standardization", "RelevanceSource", "PortableModel"}


def test_every_estimator_and_fitted_object_users_pickle_carries_the_version():
    from sklearn.base import BaseEstimator

    classes = _public_classes()
    for expected in ("HMMGMRRegressor", "FittedHMMGMR", "FilterStream", "PerformanceScore"):
        assert expected in classes
    missing = [
        name
        for name, cls in classes.items()
        if name not in NOT_PICKLED_ALONE and not issubclass(cls, PickleVersionMixin)
    ]
    assert not missing, missing
    estimators = [cls for cls in classes.values() if issubclass(cls, BaseEstimator)]
    assert len(estimators) >= 8
    for cls in estimators:  # the mixin first, so that it wraps scikit-learn's state
        assert cls.__mro__.index(PickleVersionMixin) < cls.__mro__.index(BaseEstimator)


def test_fit_remembers_the_names_of_the_outputs(frame, tmp_path):
    """#51 item 14: the regressor forgot ``y.name``, so that the documented
    ``portable.save(model, path, units={"driver_torque": "N m"})`` failed without
    ``output_names``."""
    from skhmmgmr import portable

    X, y, groups = frame
    model = HMMGMRRegressor(n_states=2, random_state=0)
    model.fit(X, y.rename("driver_torque"), groups=groups)
    assert list(model.output_names_) == ["driver_torque"]
    path = tmp_path / "model.json"
    portable.save(model, path, units={"driver_torque": "N m"})
    restored, training = portable.load(path, return_training=True)
    assert training["units"] == {"driver_torque": "N m"}
    assert list(restored.output_names_) == ["driver_torque"]
    # several outputs: a DataFrame's columns
    both = pd.DataFrame({"driver_torque": y, "rack_force": 3 * y})
    model.fit(X, both, groups=groups)
    assert list(model.output_names_) == ["driver_torque", "rack_force"]
    # names given to save win; an unnamed y leaves none (a refit forgets the old ones)
    portable.save(model, path, output_names=["a", "b"])
    assert list(portable.load(path).output_names_) == ["a", "b"]
    for unnamed in (y.rename(None), y.to_numpy(), both.set_axis([0, 1], axis=1)):
        model.fit(X, unnamed, groups=groups)
        assert not hasattr(model, "output_names_")
        portable.save(model, path)
        assert not hasattr(portable.load(path), "output_names_")
