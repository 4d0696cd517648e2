"""scikit-learn's estimator checks on every public estimator, with the expected failures that
:func:`skhmmgmr.utils.expected_failed_checks` declares, and the input checks they led to."""

import inspect
import warnings

import numpy as np
import pandas as pd
import pytest
import scipy.sparse as sp
from sklearn.base import BaseEstimator, clone
from sklearn.exceptions import SkipTestWarning
from sklearn.model_selection import PredefinedSplit, ShuffleSplit
from sklearn.utils.estimator_checks import (
    check_estimator,
    estimator_checks_generator,
    parametrize_with_checks,
)

import skhmmgmr
from skhmmgmr import (
    ExhaustiveFeatureSelector,
    ForwardFeatureSelector,
    HierarchicalHMMGMRRegressor,
    HMMGMRRegressor,
    SpearmanSelector,
    StateSelector,
    SteeringFeatures,
    make_driver_model,
)
from skhmmgmr.utils import expected_failed_checks

PERIOD = 0.05
# The checks fit without groups, so their rows form one recording: a search then needs a cv
# that validates part of that recording, in one split.
ONE_RECORDING = ShuffleSplit(n_splits=1, test_size=0.5, random_state=0)
SEARCH = {"sampling_period": PERIOD, "cv": ONE_RECORDING}

DRIVER_MODEL_CHECKED = dict(
    friction_velocity=0.1,
    velocity_filter=None,
    friction_column=0,
    load_columns=(0,),
    output_smoothing=None,
    random_state=0,
)
# Every public estimator, with small valid parameters under which every check can run.
ESTIMATORS = [
    HMMGMRRegressor(n_states=2, random_state=0),
    # NaN inputs marginalised: allow_nan, so the checks also fit and predict with NaN
    HMMGMRRegressor(n_states=2, missing_values="marginalize", random_state=0),
    HMMGMRRegressor(n_states=2, missing_values="carry_forward", random_state=0),
    # two manoeuvres of one state each, found by k-means (the checks pass no labels)
    HierarchicalHMMGMRRegressor(n_states=1, random_state=0),
    HierarchicalHMMGMRRegressor(n_states=1, missing_values="marginalize", random_state=0),
    SpearmanSelector(k=1),
    ExhaustiveFeatureSelector(max_features=1, **SEARCH),
    ForwardFeatureSelector(max_features=1, **SEARCH),
    # K >= 2 whatever the data: predict is then a causal filter, as the declared failures say
    StateSelector(k_min=2, k_max=3, **SEARCH),
    # columns by position: the checks pass arrays without names, some with a single column
    SteeringFeatures(friction_column=0, load_columns=(0,)),
    # the friction band chosen in fit, on the target the checks give
    SteeringFeatures(friction_velocity="auto", friction_column=0, load_columns=(0,)),
    # the driver model (a Pipeline): columns by position, no read-out across rows; one state,
    # then two (a causal filter, as the regressor's)
    make_driver_model(**DRIVER_MODEL_CHECKED),
    make_driver_model(2, **DRIVER_MODEL_CHECKED),
]
# Configurations as users write them, for which fit (or predict) cannot run on the checks'
# data: every check that needs it is declared, and must fail.
CANNOT_RUN = [
    ExhaustiveFeatureSelector(max_features=1, sampling_period=PERIOD, cv=2),
    ForwardFeatureSelector(max_features=1, sampling_period=PERIOD, cv=2),
    StateSelector(k_max=2, sampling_period=PERIOD, cv=2),
    StateSelector(k_max=2, sampling_period=PERIOD, cv=PredefinedSplit(np.repeat([-1, 0], 1000))),
    StateSelector(k_max=2, cv=ONE_RECORDING),  # no sampling_period
    StateSelector(k_max=1, refit=False, **SEARCH),
]


# Strict: a declared failure that passes fails the test, so the declarations stay exact.
@parametrize_with_checks(
    ESTIMATORS, expected_failed_checks=expected_failed_checks, xfail_strict=True
)
def test_sklearn_compatible_estimator(estimator, check):
    check(estimator)


@pytest.mark.parametrize("estimator", CANNOT_RUN, ids=lambda e: " ".join(repr(e).split()))
def test_configurations_that_cannot_run_fail_exactly_the_declared_checks(estimator):
    """As users would run them: ``check_estimator`` with the declared failures."""
    declared = expected_failed_checks(estimator)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SkipTestWarning)
        results = check_estimator(estimator, expected_failed_checks=declared, on_fail=None)
    status = {(r["check_name"], r["status"]) for r in results}
    assert {name for name, s in status if s == "failed"} == set()
    assert {name for name, s in status if s == "xfail"} == set(declared)
    assert {name for name, s in status if s == "passed"}.isdisjoint(declared)


def test_every_public_estimator_is_checked():
    public = {
        obj
        for name in skhmmgmr.__all__
        if inspect.isclass(obj := getattr(skhmmgmr, name)) and issubclass(obj, BaseEstimator)
    }
    # and what the public factories build (the torque pipeline is checked as a driver model)
    public.add(type(make_driver_model()))
    assert public == {type(estimator) for estimator in ESTIMATORS}


def _check_name(check):
    while hasattr(check, "__wrapped__"):
        check = check.__wrapped__
    return getattr(check, "func", check).__name__


@pytest.mark.parametrize(
    "estimator",
    [
        *ESTIMATORS,
        *CANNOT_RUN,
        HMMGMRRegressor(n_states=1),
        HierarchicalHMMGMRRegressor(manoeuvres=1, n_states=1),
        StateSelector(k_max=1, **SEARCH),
        StateSelector(sampling_period=PERIOD),
        ExhaustiveFeatureSelector(),
        ForwardFeatureSelector(sampling_period=PERIOD, cv=PredefinedSplit([0, -1, -1])),
    ],
)
def test_expected_failures_name_existing_checks_with_a_reason(estimator):
    declared = expected_failed_checks(estimator)
    checks = {_check_name(check) for _, check in estimator_checks_generator(estimator)}
    assert set(declared) <= checks, f"no such checks: {set(declared) - checks}"
    for name, reason in declared.items():
        assert isinstance(reason, str), name
        assert reason == reason.strip() and reason.endswith("."), (name, reason)
        assert len(reason.split()) >= 8, (name, reason)


def test_no_expected_failure_without_a_cause():
    assert expected_failed_checks(HMMGMRRegressor(n_states=1)) == {}
    assert expected_failed_checks(StateSelector(k_max=1, **SEARCH)) == {}
    assert expected_failed_checks(SpearmanSelector()) == {}
    assert expected_failed_checks(BaseEstimator()) == {}


def test_the_reason_says_why_the_search_cannot_fit():
    reasons = set(expected_failed_checks(StateSelector(cv=3, sampling_period=PERIOD)).values())
    assert len(reasons) == 1
    assert "cv=3 splits the recordings with GroupKFold" in reasons.pop()
    reasons = set(expected_failed_checks(StateSelector(cv=ONE_RECORDING)).values())
    assert "sampling_period is None" in reasons.pop()


# -- input checks the common checks led to -------------------------------------------------


def _recordings():
    """Two training recordings and one validation recording, with named columns."""
    rng = np.random.default_rng(0)
    X = pd.DataFrame(rng.normal(size=(60, 2)), columns=["speed", "angle"])
    y = X["speed"].to_numpy() + 0.1 * rng.normal(size=60)
    groups = np.repeat(["r0", "r1", "r2"], 20)
    return X, y, groups


SELECTORS = [
    SpearmanSelector(k=1),
    ExhaustiveFeatureSelector(
        sampling_period=PERIOD, cv=PredefinedSplit(np.repeat([-1, -1, 0], 20))
    ),
    ForwardFeatureSelector(sampling_period=PERIOD, cv=PredefinedSplit(np.repeat([-1, -1, 0], 20))),
    StateSelector(k_max=2, sampling_period=PERIOD, cv=PredefinedSplit(np.repeat([-1, -1, 0], 20))),
]


@pytest.mark.parametrize("selector", SELECTORS, ids=lambda s: type(s).__name__)
@pytest.mark.parametrize("bad, kind", [(np.nan, "NaN"), (np.inf, "infinity")])
def test_a_non_finite_feature_is_refused_naming_its_column_and_recording(selector, bad, kind):
    X, y, groups = _recordings()
    X.iloc[25, 1] = bad
    message = f"X contains {kind} in column 'angle' of recording 'r1' \\(row 5 of the recording"
    with pytest.raises(ValueError, match=message):
        clone(selector).fit(X, y, groups=groups)


@pytest.mark.parametrize("selector", SELECTORS, ids=lambda s: type(s).__name__)
def test_a_non_finite_target_is_refused_naming_its_recording(selector):
    X, y, groups = _recordings()
    y[45] = np.nan
    with pytest.raises(ValueError, match="y contains NaN in column 'output 0' of recording 'r2'"):
        clone(selector).fit(X, y, groups=groups)


@pytest.mark.parametrize("selector", SELECTORS, ids=lambda s: type(s).__name__)
def test_sparse_input_is_refused_saying_so(selector):
    X, y, groups = _recordings()
    with pytest.raises(TypeError, match="[Ss]parse data was passed for X, but dense data"):
        clone(selector).fit(sp.csr_matrix(X.to_numpy()), y, groups=groups)


@pytest.mark.parametrize("selector", SELECTORS[1:], ids=lambda s: type(s).__name__)
def test_a_search_needs_two_rows(selector):
    with pytest.raises(ValueError, match="Found array with 1 sample"):
        clone(selector).fit(np.zeros((1, 2)), np.zeros(1))


@pytest.mark.parametrize("selector", SELECTORS[1:], ids=lambda s: type(s).__name__)
def test_bad_data_is_named_before_a_missing_sampling_period(selector):
    X, y, groups = _recordings()
    X.iloc[3, 0] = np.nan
    with pytest.raises(ValueError, match="NaN in column 'speed'"):
        clone(selector).set_params(sampling_period=None).fit(X, y, groups=groups)
