"""The exhaustive wrapper of the thesis (Section IV-B, method 1): one model per non-empty
feature subset, every subset scored on every validation recording and re-scorable for any
trade-off.

The wrapper fits on the training recordings of each ``cv`` split and judges on its validation
recordings. For the thesis' fixed validation set use
``PredefinedSplit(np.where(is_validation_row, 0, -1))``; an integer ``cv`` means
``GroupKFold(cv)``, so that every recording is validated once by a model that never saw it.
Public through :mod:`skhmmgmr.feature_selection`.
"""

import itertools
from numbers import Integral

import numpy as np
from sklearn.utils.validation import check_is_fitted

from ..._core._compat import Interval, _fit_context
from ..._core._docstrings import fill_shared_parameters
from ...metrics._scores import trade_offs as all_trade_offs
from .._search import _screening
from .._search._decisions import count_thresholds, normalised_bounds, relevance_to_confirm
from .._search._score_tables import (
    best_on_average,
    best_per_recording,
    labels_of,
    rescore_table,
)
from .._search.base import RecordingSelector


@fill_shared_parameters
class ExhaustiveFeatureSelector(RecordingSelector):
    """Method 1 of the thesis: one model per non-empty feature subset, judged per recording.

    For every subset of ``min_features`` to ``max_features`` features a clone of ``estimator``
    is fitted on the training recordings of each ``cv`` split and evaluated (RMSE, accuracy,
    smoothness) on each validation recording. The tidy table ``results_`` keeps every (subset,
    recording) metric, so any accuracy/smoothness trade-off is re-scored without retraining
    (:meth:`rescore`, :meth:`best_subsets`). The selected subset (``get_support``) is the one
    with the lowest D.5-normalised performance score averaged over the validation recordings,
    at ``accuracy_weight``/``smoothness_weight``.

    Parameters
    ----------
    {estimator}
    max_features : int, default=None
        Largest subset size; ``None`` means all features (``2**n - 1`` subsets).
    min_features : int, default=1
        Smallest subset size.
    {search parameters}

    Attributes
    ----------
    results_ : pandas.DataFrame
        One row per (subset, validation recording): ``subset`` (tuple of feature names),
        ``n_features``, ``fold``, ``recording``, ``n_samples``, ``rmse``, ``accuracy``,
        ``smoothness``, ``converged``.
    subset_ : tuple of str
        Selected feature subset.
    support_ : ndarray of shape (n_features,)
        Mask of the selected subset.
    n_features_in_, feature_names_in_
        As in scikit-learn.

    Examples
    --------
    >>> import numpy as np
    >>> from sklearn.model_selection import PredefinedSplit
    >>> from skhmmgmr.feature_selection import ExhaustiveFeatureSelector
    >>> rng = np.random.default_rng(0)
    >>> X = np.cumsum(rng.normal(scale=0.1, size=(400, 3)), axis=0)
    >>> y = 2 * X[:, 0] + 0.01 * rng.normal(size=400)
    >>> groups = np.repeat([0, 1, 2, 3], 100)
    >>> cv = PredefinedSplit(np.where(groups >= 2, 0, -1))
    >>> selector = ExhaustiveFeatureSelector(cv=cv, sampling_period=0.1, smoothness_weight=0)
    >>> selector.fit(X, y, groups=groups).results_["subset"].nunique()
    7
    """

    _parameter_constraints = {
        **RecordingSelector._parameter_constraints,
        "max_features": [Interval(Integral, 1, None, closed="left"), None],
        "min_features": [Interval(Integral, 1, None, closed="left")],
    }

    def __init__(
        self,
        estimator=None,
        *,
        max_features=None,
        min_features=1,
        cv=5,
        accuracy_weight=0.5,
        smoothness_weight=0.5,
        sampling_period=None,
        n_jobs=None,
        memory=None,
        verbose=0,
        search="full",
    ):
        super().__init__(
            estimator,
            cv=cv,
            accuracy_weight=accuracy_weight,
            smoothness_weight=smoothness_weight,
            sampling_period=sampling_period,
            n_jobs=n_jobs,
            memory=memory,
            verbose=verbose,
            search=search,
        )
        self.max_features = max_features
        self.min_features = min_features

    @_fit_context(prefer_skip_nested_validation=False)
    def fit(self, X, y, groups=None):
        """Fit and evaluate one model per feature subset.

        Parameters
        ----------
        X : array-like of shape (n_samples, n_features)
            Candidate features of the training and validation recordings.
        y : array-like of shape (n_samples,)
            Target (driver torque).
        groups : array-like of shape (n_samples,), default=None
            Recording id of every row.

        Returns
        -------
        self : ExhaustiveFeatureSelector
        """
        X, y, groups, splits = self._validate_search(X, y, groups)
        n_features = X.shape[1]
        largest = n_features if self.max_features is None else min(self.max_features, n_features)
        if self.min_features > largest:
            raise ValueError(f"min_features={self.min_features} > max_features={largest}")
        subsets = [
            subset
            for size in range(self.min_features, largest + 1)
            for subset in itertools.combinations(range(n_features), size)
        ]
        trade_offs = [*all_trade_offs(10), *labels_of(self._trade_off)]

        tolerance = _screening.SCREENING_ERROR

        def settle(table):
            # the fast search fits in full what can move a decision of the relevance (at
            # every trade-off of a 10 % grid) or the best subset on average
            scores = rescore_table(table, "model", trade_offs)
            n_recordings = table["recording"].nunique()
            chosen = relevance_to_confirm(
                scores,
                "model",
                lambda model: subsets[model],
                tolerance,
                count_thresholds(n_recordings),
            )
            own = rescore_table(table, "model", self._trade_off)
            low, high = normalised_bounds(own, tolerance)
            means = own.assign(low=low, high=high).groupby("model", sort=False)
            means = means.agg(
                low=("low", "mean"), high=("high", "mean"), screened=("screened", "any")
            )
            best = means["low"] <= means["high"].min()
            return chosen | set(means.index[best & means["screened"]])

        with self._searching(X, y, groups, splits):
            self.results_ = self._evaluate_subsets(
                X,
                y,
                groups,
                splits,
                subsets,
                "feature subsets",
                settle=None if tolerance is None else settle,
            )
        best = self.best_subsets(self._trade_off, per_recording=False)
        self.subset_ = best["subset"].iloc[0]
        self.support_ = np.isin(self._names(), self.subset_)
        return self

    def _subset_iterations(self):
        # every subset is screened: the fast search scores the joint model's marginals
        return _screening.EXHAUSTIVE_ITERATIONS

    def rescore(self, trade_off="50/50"):
        """D.5-normalised performance score of every (subset, recording), without refitting.

        Parameters
        ----------
        trade_off : str, pair or list of those, default="50/50"
            Trade-off(s) "accuracy/smoothness" in percent, or ``(w1, w2)`` pairs.

        Returns
        -------
        scores : pandas.DataFrame
            ``results_`` with ``trade_off``, weights, ``accuracy_term``, ``smoothness_term`` and
            ``performance_score`` (lower is better), one block per trade-off.
        """
        check_is_fitted(self, "results_")
        return rescore_table(self.results_, "subset", trade_off)

    def best_subsets(self, trade_off="50/50", per_recording=True):
        """Best subset per validation recording (or on average), for each trade-off.

        Parameters
        ----------
        trade_off : str, pair or list of those, default="50/50"
        per_recording : bool, default=True
            If True, the subset with the lowest score on each recording (the thesis' input to
            feature relevance); if False, the subset with the lowest mean score. Ties go to the
            smaller subset.

        Returns
        -------
        best : pandas.DataFrame
            One row per (trade-off, recording) or per trade-off, with ``subset``,
            ``n_features``, ``performance_score``, ``accuracy`` and ``smoothness``.
        """
        scores = self.rescore(trade_off)
        if per_recording:
            return best_per_recording(scores, "subset", tie_breaker="n_features")
        return best_on_average(scores, "subset", tie_breaker="n_features")
