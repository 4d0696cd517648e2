"""What a :class:`~skhmmgmr.FilterStream` streams, and with which settings.

A stream is made of a :class:`~skhmmgmr.FittedHMMGMR`, of a fitted estimator (its ``model_``)
or of a fitted Pipeline of ``SteeringFeatures`` steps ending in one
(:func:`~skhmmgmr.streaming._derived.read_pipeline`). The settings the stream does not get
are the estimator's (the regressor's, for a Pipeline), so that the stream filters as
``predict`` does: its ``missing_values`` and its outlier policy, ``min_log_density``
(:mod:`skhmmgmr._hmm._holds`).
"""

from dataclasses import dataclass

from sklearn.utils.validation import check_is_fitted

from .._hmm._fitted import FittedHMMGMR
from .._hmm._holds import check_min_log_density
from .._hmm._stale_inputs import MISSING_VALUES
from ._derived import check_final, read_pipeline


@dataclass(frozen=True)
class Streamed:
    """The model a stream filters with, its derived-input ``stages`` (a Pipeline's; empty
    otherwise), the raw inputs it reads (``n_features``, ``names`` or None) and the settings
    ``missing_values`` and ``min_log_density`` (None: no sample held by its density)."""

    model: FittedHMMGMR
    stages: tuple
    n_features: int
    names: object
    missing_values: str
    min_log_density: object


def read_streamed(model, *, missing_values=None, min_log_density=None):
    """The :class:`Streamed` of ``model``; the settings not given (None) are the estimator's,
    "error" and None for a bare :class:`~skhmmgmr.FittedHMMGMR`."""
    estimator = None if isinstance(model, FittedHMMGMR) else model
    stages = ()
    if estimator is not None and hasattr(estimator, "steps"):  # a Pipeline
        stages, (name, estimator) = read_pipeline(estimator)
    if estimator is not None:  # a fitted estimator first, as its other methods check
        check_is_fitted(estimator)
        model = getattr(estimator, "model_", None)
        if not isinstance(model, FittedHMMGMR):
            raise TypeError(
                "FilterStream streams a fitted HMMGMRRegressor, a FittedHMMGMR or a fitted "
                f"Pipeline ending in an HMMGMRRegressor; got {type(estimator).__name__}"
                + (f" (the Pipeline's step {name!r})" if stages else "")
            )
    if min_log_density is None:
        min_log_density = getattr(estimator, "min_log_density", None)
    if missing_values is None:
        missing_values = getattr(estimator, "missing_values", "error")
    if missing_values not in MISSING_VALUES:
        raise ValueError(f"missing_values must be one of {MISSING_VALUES}, got {missing_values!r}")
    n_features, names = model.n_inputs, model.feature_names
    if stages:
        check_final(stages, n_features, names)
        n_features, names = stages[0].n_features_in, stages[0].feature_names_in
    return Streamed(
        model,
        tuple(stages),
        n_features,
        names,
        missing_values,
        check_min_log_density(min_log_density, "FilterStream"),
    )
