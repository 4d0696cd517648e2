"""The scikit-learn estimator checks that cannot hold for the package's estimators, and why.

:func:`expected_failed_checks` returns, for an estimator of the package as configured, the
checks of :func:`sklearn.utils.estimator_checks.check_estimator` it fails by design, each with
its reason: predictions are a causal filter over the rows of a recording, and the searches
split recordings, which the checks (no ``groups``, so one recording) cannot give them.
Public through :mod:`skhmmgmr.utils`.
"""

from numbers import Integral

import numpy as np
from sklearn.model_selection import PredefinedSplit
from sklearn.pipeline import Pipeline

from ..._core._compat import HasMethods, validate_params
from ...estimator import HierarchicalHMMGMRRegressor, HMMGMRRegressor
from .._search._evaluation import check_recording_splits
from .._search.base import RecordingSearchMixin
from ._states import StateSelector

# Why a causal filter fails each check
FILTER_WHY = {
    "check_methods_sample_order_invariance": (
        "the estimate of a row depends on the rows before it (the forward variable of the "
        "HMM), so it changes when the rows are reordered. A filter that ignored the order of "
        "the rows would discard the model's dynamics."
    ),
    "check_methods_subset_invariance": (
        "predicting a subset of the rows restarts the filter at the first row of the subset, "
        "so the estimate of a row depends on the rows given before it. To predict a recording "
        "in batches with the same estimates, carry the filter's state from batch to batch "
        "with filter_stream()."
    ),
}

# scikit-learn's own expected failures of a Pipeline
PIPELINE_WHY = dict.fromkeys(
    ("check_dont_overwrite_parameters", "check_estimators_overwrite_params"),
    "a scikit-learn Pipeline fits the estimators of its steps parameter in place.",
)
# The checks that fit the estimator: all of them fail when fit cannot run on the checks' data.
FIT_CHECKS = (
    "check_dict_unchanged",
    "check_dont_overwrite_parameters",
    "check_dtype_object",
    "check_estimators_dtypes",
    "check_estimators_fit_returns_self",
    "check_estimators_nan_inf",
    "check_estimators_overwrite_params",
    "check_estimators_pickle",
    "check_f_contiguous_array_estimator",
    "check_fit2d_1feature",
    "check_fit2d_predict1d",
    "check_fit_check_is_fitted",
    "check_fit_idempotent",
    "check_fit_score_takes_y",
    "check_methods_sample_order_invariance",
    "check_methods_subset_invariance",
    "check_n_features_in",
    "check_n_features_in_after_fitting",
    "check_pipeline_consistency",
    "check_positive_only_tag_during_fit",
    "check_readonly_memmap_input",
)
TRANSFORMER_FIT_CHECKS = (
    "check_transformer_data_not_an_array",
    "check_transformer_general",
    "check_transformer_preserve_dtypes",
)
REGRESSOR_FIT_CHECKS = (
    "check_regressor_data_not_an_array",
    "check_regressors_int",
    "check_regressors_no_decision_function",
    "check_regressors_train",
    "check_supervised_y_2d",
)
# The checks of a fitted StateSelector that call predict (or score, which predicts).
PREDICT_CHECKS = (
    "check_dict_unchanged",
    "check_dtype_object",
    "check_estimators_dtypes",
    "check_estimators_nan_inf",
    "check_estimators_pickle",
    "check_f_contiguous_array_estimator",
    "check_fit2d_predict1d",
    "check_fit_idempotent",
    "check_fit_score_takes_y",
    "check_methods_sample_order_invariance",
    "check_methods_subset_invariance",
    "check_n_features_in_after_fitting",
    "check_pipeline_consistency",
    "check_regressor_data_not_an_array",
    "check_regressors_int",
    "check_regressors_train",
    "check_supervised_y_2d",
)

ONE_RECORDING = (
    "scikit-learn's checks fit without groups, so all their rows form one recording, and"
)
A_SPLITTER = (
    "To run these checks, give a cv that validates part of one recording in a single split, "
    "such as ShuffleSplit(n_splits=1, test_size=0.5, random_state=0)."
)


def _why_the_search_cannot_fit(search):
    """Why ``fit`` of a search fails on every data set of the checks, or None if it runs."""
    if search.sampling_period is None:
        return (
            "fit cannot run: sampling_period is None, and the smoothness metric of every "
            "evaluation needs the seconds between two rows. Give sampling_period."
        )
    if search.accuracy_weight == 0 and search.smoothness_weight == 0:
        return (
            "fit cannot run: accuracy_weight and smoothness_weight are both 0, so no model can "
            "be preferred to another. Give one of them a positive weight."
        )
    if isinstance(search.cv, Integral):
        return (
            f"fit cannot run: {ONE_RECORDING} cv={search.cv} splits the recordings with "
            f"GroupKFold, which cannot split one recording. {A_SPLITTER}"
        )
    if isinstance(search.cv, PredefinedSplit) or not hasattr(search.cv, "split"):
        return (
            "fit cannot run: cv holds fixed (train, validation) row indices, made for one data "
            "set, and scikit-learn's checks fit on data sets of their own. " + A_SPLITTER
        )
    # A splitter: does it split one recording, each validated part scored once?
    n_samples = 20
    try:
        check_recording_splits(search.cv, np.zeros((n_samples, 1)), np.arange(n_samples), None)
    except (ValueError, TypeError, IndexError) as error:
        cause = str(error).split(";")[0].rstrip(".")
        return (
            f"fit cannot run: {ONE_RECORDING} cv={search.cv!r} cannot split it ({cause}). "
            + A_SPLITTER
        )
    return None


# What check_estimator checks: an estimator (it clones it, through get_params).
@validate_params({"estimator": [HasMethods(["get_params"])]}, prefer_skip_nested_validation=True)
def expected_failed_checks(estimator):
    """The scikit-learn estimator checks that ``estimator`` fails by design, and why.

    Pass the result to :func:`~sklearn.utils.estimator_checks.check_estimator` (or the
    function itself to :func:`~sklearn.utils.estimator_checks.parametrize_with_checks`) to
    run scikit-learn's checks on your own configuration: every other check must pass.

    Two kinds of checks cannot hold:

    - predictions are a causal filter over the rows of a recording (the HMM's forward
      variable), so they change when rows are reordered or predicted in subsets
      (:class:`~skhmmgmr.HMMGMRRegressor` with ``n_states >= 2``, and
      :class:`~skhmmgmr.StateSelector`, which predicts with it);
    - the checks fit without ``groups``, so their rows form one recording: a search whose
      ``cv`` splits recordings (an integer ``cv`` means ``GroupKFold``) cannot fit, nor one
      whose ``cv`` holds the row indices of another data set (``PredefinedSplit``), nor one
      without ``sampling_period``, so every check that fits fails. A ``cv`` that validates
      part of one recording in a single split (``ShuffleSplit(n_splits=1)``) runs them.

    With ``refit=False``, :class:`~skhmmgmr.StateSelector` cannot predict, so the checks that
    predict fail too. A ``Pipeline`` (a torque pipeline, a driver model) fails what its last
    step fails, and the two checks scikit-learn declares for every ``Pipeline`` (it fits the
    estimators of its ``steps`` parameter in place).

    Parameters
    ----------
    estimator : estimator instance
        An estimator of the package, configured as it will be checked. Any other estimator
        has no expected failure here (an empty dict).

    Returns
    -------
    expected_failed_checks : dict of str to str
        ``{check name: reason}``, a sentence per check.

    Examples
    --------
    >>> from sklearn.model_selection import ShuffleSplit
    >>> from skhmmgmr import HMMGMRRegressor, StateSelector
    >>> from skhmmgmr.utils import expected_failed_checks
    >>> sorted(expected_failed_checks(HMMGMRRegressor(n_states=2)))
    ['check_methods_sample_order_invariance', 'check_methods_subset_invariance']
    >>> len(expected_failed_checks(StateSelector(cv=5, sampling_period=0.05)))
    26
    >>> one_recording = ShuffleSplit(n_splits=1, test_size=0.5, random_state=0)
    >>> len(expected_failed_checks(StateSelector(cv=one_recording, sampling_period=0.05)))
    2

    With scikit-learn's checks (a few seconds)::

        from sklearn.utils.estimator_checks import check_estimator

        estimator = HMMGMRRegressor(n_states=3, covariance_type="tied")
        check_estimator(estimator, expected_failed_checks=expected_failed_checks(estimator))
    """
    if isinstance(estimator, Pipeline) and estimator.steps:  # a torque pipeline, a driver model
        failures = expected_failed_checks(estimator.steps[-1][1])
        return {**failures, **PIPELINE_WHY}
    if isinstance(estimator, HMMGMRRegressor):
        n_states = (
            estimator.total_states()
            if isinstance(estimator, HierarchicalHMMGMRRegressor)
            else estimator.n_states
        )
        if n_states is not None and n_states < 2:
            return {}  # one state: the estimate of a row is that row's conditional mean
        return {
            name: f"predict is a causal filter over the rows of a recording: {why}"
            for name, why in FILTER_WHY.items()
        }
    if not isinstance(estimator, RecordingSearchMixin):
        return {}
    is_state_selector = isinstance(estimator, StateSelector)
    reason = _why_the_search_cannot_fit(estimator)
    if reason is not None:
        own = REGRESSOR_FIT_CHECKS if is_state_selector else TRANSFORMER_FIT_CHECKS
        return dict.fromkeys(sorted(FIT_CHECKS + own), reason)
    if not is_state_selector:
        return {}  # transform keeps columns: no filter over rows
    if not estimator.refit:
        reason = (
            "predict needs the estimator refitted with the chosen number of states, and "
            "refit=False refits none. Set refit=True to run these checks."
        )
        return dict.fromkeys(PREDICT_CHECKS, reason)
    if estimator.k_max < 2:
        return {}
    return {
        name: "predict is that of the refitted estimator, a causal filter over the rows of a "
        f"recording when the chosen n_states is 2 or more: {why}"
        for name, why in FILTER_WHY.items()
    }
