"""Bad input gets a clear error that names what is wrong."""

import numpy as np
import pandas as pd
import pytest
from sklearn.exceptions import NotFittedError

from skhmmgmr import HMMGMRRegressor


@pytest.fixture(scope="module")
def frame():
    rng = np.random.default_rng(0)
    n = 120
    X = pd.DataFrame(
        {
            "steering_wheel_angle": np.cumsum(rng.normal(size=n)) / 10,
            "yaw_rate": np.cumsum(rng.normal(size=n)) / 50,
        }
    )
    y = pd.Series(2 * X["steering_wheel_angle"] + rng.normal(scale=0.1, size=n), name="torque")
    groups = np.repeat(np.array(["r1", "r2", "r3"], dtype=object), 40)
    return X, y, groups


@pytest.fixture(scope="module")
def fitted(frame):
    X, y, groups = frame
    return HMMGMRRegressor(n_states=2, random_state=0).fit(X, y, groups=groups)


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_input_names_column_and_recording(frame, bad):
    X, y, groups = frame
    X = X.copy()
    X.loc[45, "yaw_rate"] = bad
    with pytest.raises(ValueError, match=r"column 'yaw_rate' of recording 'r2' \(row 5 of"):
        HMMGMRRegressor(n_states=2).fit(X, y, groups=groups)


def test_non_finite_input_at_predict_time(frame, fitted):
    X, _, groups = frame
    X = X.copy()
    X.loc[100, "steering_wheel_angle"] = np.nan
    with pytest.raises(ValueError, match=r"NaN in column 'steering_wheel_angle' of recording 'r3'"):
        fitted.predict(X, groups=groups)


def test_non_finite_target_names_recording(frame):
    X, y, groups = frame
    y = y.copy()
    y.iloc[3] = np.nan
    with pytest.raises(
        ValueError, match=r"Input y contains NaN in column 'torque' of recording 'r1'"
    ):
        HMMGMRRegressor(n_states=2).fit(X, y, groups=groups)


@pytest.mark.parametrize(
    "target",
    [
        np.array(["left", "right"] * 60),
        pd.Series(["0.1", "x"] * 60, dtype=object),
        pd.Series(["a", "b"] * 60, dtype="string"),
        np.array(["2020-01-01"] * 120, dtype="datetime64[D]"),
    ],
)
def test_non_numeric_target_is_refused(frame, target):
    X, _, groups = frame
    with pytest.raises(ValueError, match="y must be numeric"):
        HMMGMRRegressor(n_states=2).fit(X, target, groups=groups)


def test_recording_too_short_for_fit(frame):
    X, y, groups = frame
    groups = groups.copy()
    groups[-1] = "lonely"
    with pytest.raises(ValueError, match=r"recording 'lonely' has n_samples=1"):
        HMMGMRRegressor(n_states=2).fit(X, y, groups=groups)


def test_too_many_states(frame):
    X, y, _ = frame
    with pytest.raises(ValueError, match=r"n_states=200 is more than the data support"):
        HMMGMRRegressor(n_states=200).fit(X, y)


def test_few_rows_per_state_warns(frame):
    X, y, _ = frame
    with pytest.warns(UserWarning, match=r"need at least .* rows for full covariances"):
        HMMGMRRegressor(n_states=40, n_iter=3, random_state=0).fit(X, y)


@pytest.mark.parametrize(
    "param, value, match",
    [
        ("n_states", 0, "n_states"),
        ("reg_covar", -1.0, "reg_covar"),
        ("init_params", "spectral", "init_params"),
        ("n_init", 0, "n_init"),
        # a bool is an int in Python, but not a number of states, iterations or a tolerance
        ("n_states", True, r"'n_states' parameter .* \(not a bool\)\. Got True"),
        ("n_iter", np.True_, "'n_iter' parameter"),
        ("n_init", True, "'n_init' parameter"),
        ("tol", False, "'tol' parameter"),
        ("reg_covar", True, "'reg_covar' parameter"),
    ],
)
def test_invalid_parameters_are_named(frame, param, value, match):
    X, y, _ = frame
    with pytest.raises(ValueError, match=match):
        HMMGMRRegressor(**{param: value}).fit(X, y)


def test_wrong_number_of_columns(frame, fitted):
    X, _, _ = frame
    with pytest.raises(ValueError, match=r"3 features, but HMMGMRRegressor is expecting 2"):
        fitted.predict(np.column_stack([X.to_numpy(), X.to_numpy()[:, 0]]))


def test_wrong_column_names(frame, fitted):
    X, _, _ = frame
    renamed = X.rename(columns={"yaw_rate": "yaw_velocity"})
    with pytest.raises(ValueError, match=r"yaw_velocity"):
        fitted.predict(renamed)


def test_groups_of_the_wrong_length(frame, fitted):
    X, y, groups = frame
    with pytest.raises(ValueError, match=r"groups has 119 entries but X has 120 rows"):
        fitted.predict(X, groups=groups[:-1])
    with pytest.raises(ValueError, match=r"groups has 119 entries but X has 120 rows"):
        HMMGMRRegressor(n_states=2).fit(X, y, groups=groups[:-1])


def test_interleaved_recordings(frame):
    X, y, groups = frame
    groups = groups.copy()
    groups[50:55] = "r1"
    with pytest.raises(ValueError, match=r"rows of recording 'r1' are not contiguous"):
        HMMGMRRegressor(n_states=2).fit(X, y, groups=groups)


def test_time_out_of_order(frame):
    X, y, groups = frame
    time = np.tile(np.arange(40) * 0.05, 3)
    time[[10, 11]] = time[[11, 10]]
    with pytest.raises(ValueError, match=r"time does not increase within recording 'r1' at row 11"):
        HMMGMRRegressor(n_states=2).fit(X, y, groups=groups, time=time)
    ok = np.tile(np.arange(40) * 0.05, 3)
    HMMGMRRegressor(n_states=2, random_state=0).fit(X, y, groups=groups, time=ok)


def test_predict_before_fit(frame):
    X, _, _ = frame
    model = HMMGMRRegressor()
    for method in (model.predict, model.predict_state_proba, model.transform):
        with pytest.raises(NotFittedError):
            method(X)


@pytest.mark.parametrize("missing", [None, np.nan, pd.NA])
def test_missing_recording_id(frame, missing):
    X, y, groups = frame
    groups = groups.astype(object)
    groups[7:9] = missing
    with pytest.raises(ValueError, match=r"missing recording id \(first at row 7\)"):
        HMMGMRRegressor(n_states=2).fit(X, y, groups=groups)


def test_finite_interval_refuses_inf_nan_huge_ints_and_bools():
    from numbers import Real

    from skhmmgmr._core._compat import FiniteInterval

    positive = FiniteInterval(Real, 0, None, closed="neither")
    assert positive.is_satisfied_by(1e300) and positive.is_satisfied_by(7)
    for value in (float("inf"), float("nan"), 10**400, True, 0.0, -1.0):
        assert not positive.is_satisfied_by(value), value
    assert "finite" in str(positive)
