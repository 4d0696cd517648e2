"""Every public function of the selection family, of ``skhmmgmr.metrics`` and of
``skhmmgmr.plotting`` checks its arguments with scikit-learn's ``validate_params``: every
parameter has a constraint, and a bad argument is refused before any work, by an error that
names the parameter and the function."""

import inspect

import numpy as np
import pandas as pd
import pytest

from skhmmgmr import feature_selection, metrics, plotting, selection, state_selection, utils
from skhmmgmr._core._compat import InvalidParameterError

MODULES = (selection, feature_selection, state_selection, utils, metrics, plotting)
TABLE = pd.DataFrame({"model": ["a"], "recording": ["r"], "accuracy": [90.0], "smoothness": [1.0]})


def public_functions():
    return sorted(
        {
            value
            for module in MODULES
            for value in (getattr(module, name) for name in module.__all__)
            if inspect.isfunction(value)
        },
        key=lambda f: f.__qualname__,
    )


@pytest.mark.parametrize("function", public_functions(), ids=lambda f: f.__qualname__)
def test_every_parameter_of_a_public_function_has_a_constraint(function):
    constraints = function._skl_parameter_constraints  # set by validate_params
    assert set(constraints) == set(inspect.signature(function).parameters)


Y = np.arange(6.0)
BAD_CALLS = [
    # the selection family
    (selection.select_parameters, (TABLE,), {"n_top": 0}, "n_top"),
    (selection.select_parameters, (TABLE,), {"progress": "yes"}, "progress"),
    (
        selection.select_parameters,
        (TABLE,),
        {"relevance_sources": ["forward"]},
        "relevance_sources",
    ),
    (selection.candidate_subsets, ({"a": TABLE},), {"mild": 0}, "mild"),
    (selection.compare_subsets, (Y[:, None], Y, Y, {"a": ("x0",)}), {"cv": 2}, "X"),
    (selection.feature_relevance, (Y,), {}, "results"),
    (selection.one_way_anova, (TABLE,), {"by": 1, "values": "accuracy"}, "by"),
    (feature_selection.spearman_relevance, (Y[:, None], Y), {"groups": 3}, "groups"),
    (state_selection.select_n_states, (Y[:, None], Y), {"k_max": 0}, "k_max"),
    (state_selection.state_choices, (TABLE,), {"tol": -0.1}, "tol"),
    (utils.expected_failed_checks, (object(),), {}, "estimator"),
    # the metrics
    (metrics.accuracy_score, (Y, Y), {"multioutput": "variance_weighted"}, "multioutput"),
    (metrics.smoothness_score, (Y,), {"sampling_period": np.inf}, "sampling_period"),
    (metrics.performance_score, (Y, Y), {"smoothness_weight": -1}, "smoothness_weight"),
    (metrics.evaluate_recordings, (Y, 3.0), {}, "y_pred"),
    (metrics.trade_offs, (0,), {}, "step"),
    (metrics.normalize_performance, (TABLE,), {"weights": 50}, "weights"),
    (metrics.rank_models, (TABLE,), {"average": 1}, "average"),
    (metrics.make_performance_scorers, (), {"predict_mode": "fast"}, "predict_mode"),
    (metrics.lane_keeping_metrics, (TABLE,), {"vehicle_width": 0}, "vehicle_width"),
    # the figures
    (plotting.plot_estimate, (Y, Y, Y), {"figsize": 8}, "figsize"),
    (plotting.plot_relevance, (TABLE,), {"n_recordings": 0}, "n_recordings"),
    (plotting.plot_state_selection, (TABLE,), {"n_states": 2.5}, "n_states"),
    (plotting.plot_driver_comparison, (TABLE,), {"labels": ["final"]}, "labels"),
    (plotting.driver_table, (TABLE.to_numpy(),), {}, "test"),
]


@pytest.mark.parametrize(
    "function, args, kwargs, parameter",
    BAD_CALLS,
    ids=[f"{f.__name__}-{p}" for f, _, _, p in BAD_CALLS],
)
def test_a_bad_argument_is_refused_naming_the_parameter_and_the_function(
    function, args, kwargs, parameter
):
    with pytest.raises(
        InvalidParameterError, match=f"'{parameter}' parameter of {function.__name__}"
    ):
        function(*args, **kwargs)


def test_every_public_function_is_among_the_bad_calls():
    assert {f for f, _, _, _ in BAD_CALLS} == set(public_functions())
