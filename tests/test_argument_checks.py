"""Every public function of the package checks its arguments with scikit-learn's
``validate_params``: every parameter has a constraint, and a bad argument is refused before any
work, by an error that names the parameter and the function.

Left out, each for its reason: functions without parameters (``portable.json_schema``), the
deprecated aliases (thin calls of what replaces them, removed in 0.3),
``make_torque_pipeline`` (it only builds the pipeline: its steps check the parameters in
``fit``, as scikit-learn's estimators do), ``skhmmgmr.legacy`` (on the ground floor beside
``_core``, which it may not import) and ``skhmmgmr.cluster`` (an optional extra whose
functions take the estimator to fit, whose own parameter errors ``validate_params`` would
give the function's name), and the command line's functions (they take parsed options).
"""

import inspect

import numpy as np
import pandas as pd
import pytest

from skhmmgmr import (
    datasets,
    export,
    feature_selection,
    metrics,
    plotting,
    portable,
    selection,
    state_selection,
    utils,
)
from skhmmgmr._core._compat import InvalidParameterError

MODULES = (
    selection,
    feature_selection,
    state_selection,
    utils,
    metrics,
    plotting,
    datasets,
    export,
    portable,
)
TABLE = pd.DataFrame({"model": ["a"], "recording": ["r"], "accuracy": [90.0], "smoothness": [1.0]})


def _checked(function):
    """Whether the rule asks ``function`` for its constraints: it takes parameters and is no
    deprecated alias."""
    deprecated = ".. deprecated::" in (function.__doc__ or "")
    return bool(inspect.signature(function).parameters) and not deprecated


def public_functions():
    return sorted(
        {
            value
            for module in MODULES
            for value in (getattr(module, name) for name in module.__all__)
            if inspect.isfunction(value) and _checked(value)
        },
        key=lambda f: f.__qualname__,
    )


@pytest.mark.parametrize("function", public_functions(), ids=lambda f: f.__qualname__)
def test_every_parameter_of_a_public_function_has_a_constraint(function):
    constraints = function._skl_parameter_constraints  # set by validate_params
    assert set(constraints) == set(inspect.signature(function).parameters)


def test_the_rule_leaves_out_only_what_it_says():
    left_out = {
        f"{module.__name__}.{name}"
        for module in MODULES
        for name in module.__all__
        if inspect.isfunction(getattr(module, name)) and not _checked(getattr(module, name))
    }
    assert left_out == {
        "skhmmgmr.portable.json_schema",
        "skhmmgmr.portable.to_dict",
        "skhmmgmr.portable.export_json",
        "skhmmgmr.portable.load_json",
        "skhmmgmr.portable.read_model",
    }


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
    (selection.make_closed_loop_scorer, (), {"aggregate": "median"}, "aggregate"),
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
    # the datasets
    (datasets.calibration_table, (TABLE,), {"by": "split"}, "by"),
    (datasets.drive, ("defensive",), {"split": 1}, "split"),
    (datasets.drive, ("defensive",), {"duration": -1.0}, "duration"),
    (datasets.draw_vehicle, (), {"random_state": "seed"}, "random_state"),
    (datasets.make_driving_protocol, (), {"cache": 3}, "cache"),
    (datasets.make_driving_protocol, (), {"perturbed_share": 1.5}, "perturbed_share"),
    (datasets.make_lane_keeping, (), {"driver": "racer"}, "driver"),
    (datasets.make_lane_keeping, (), {"sampling_rate": True}, "sampling_rate"),
    (datasets.get_data_home, (3,), {}, "data_home"),
    (datasets.clear_data_home, (3,), {}, "data_home"),
    (datasets.fetch_comma2k19, (), {"method": "torrent"}, "method"),
    (datasets.fetch_comma2k19, (), {"chunks": 11}, "chunks"),
    (datasets.load_comma2k19_sample, (), {"min_span": -1.0}, "min_span"),
    (datasets.load_comma2k19_segment, (3,), {}, "path"),
    (datasets.load_recordings, (TABLE,), {"allow_missing": "yes"}, "allow_missing"),
    (datasets.resample_recordings, (TABLE.to_numpy(), 10.0), {"max_gap": 1.0}, "frame"),
    (datasets.scan_comma2k19, (), {"timeout": 0}, "timeout"),
    (datasets.shift_target, (Y, 1.5), {}, "horizon_rows"),
    (datasets.torque_ahead, (object(),), {}, "model"),
    (datasets.to_panel, (Y,), {}, "frame"),
    # the exports and the model file
    (export.write_c, (object(), "."), {"overwrite": "yes"}, "overwrite"),
    (export.write_fmu, (object(), "m.fmu"), {"fmi_version": "1.0"}, "fmi_version"),
    (export.write_fmu, (object(), "m.fmu"), {"sampling_period": np.inf}, "sampling_period"),
    (portable.save, (object(), 3), {}, "path"),
    (portable.load, ("m.json",), {"return_training": "yes"}, "return_training"),
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
