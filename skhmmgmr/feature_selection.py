"""Feature selection of the thesis (Section IV-B): a Spearman filter and two wrappers.

- :func:`spearman_relevance` / :class:`SpearmanSelector`: absolute Spearman correlation with the
  torque, averaged over recordings (Table II);
- :class:`ExhaustiveFeatureSelector` (method 1): one model per non-empty feature subset, every
  subset scored on every validation recording, re-scorable for any trade-off;
- :class:`ForwardFeatureSelector` (method 2): sequential forward selection with the 1% rule,
  on the average over validation recordings or one path per recording.

The wrappers fit on the training recordings of each ``cv`` split and judge on its validation
recordings. For the thesis' fixed validation set use
``PredefinedSplit(np.where(is_validation_row, 0, -1))``; an integer ``cv`` means
``GroupKFold(cv)``, so that every recording is validated once by a model that never saw it.
"""

import itertools
import warnings
from numbers import Integral, Real

import numpy as np
import pandas as pd
from scipy import stats
from sklearn.base import BaseEstimator
from sklearn.feature_selection import SelectorMixin
from sklearn.utils.validation import check_is_fitted, validate_data

from ._compat import Interval, StrOptions, _fit_context
from ._metrics_table import parse_trade_offs
from ._search import (
    ForwardPath,
    FrozenScores,
    RecordingSelector,
    best_on_average,
    best_per_recording,
    labels_of,
    paths_table,
    rescore_table,
)
from ._sequences import as_recordings

__all__ = [
    "ExhaustiveFeatureSelector",
    "ForwardFeatureSelector",
    "SpearmanSelector",
    "spearman_relevance",
]


# --------------------------------------------------------------------------------------------
# Filter
# --------------------------------------------------------------------------------------------


def spearman_relevance(X, y, *, groups=None):
    """Absolute Spearman correlation of every feature with the torque, averaged over recordings.

    The correlation is computed within every recording and its absolute value averaged over
    the recordings with equal weight (the thesis' Table II), not on the pooled rows: pooling
    would mix between-recording offsets into the ranking. A feature that is constant in a
    recording has no correlation there and is left out of that recording's average.

    Usable as ``SelectKBest(score_func=spearman_relevance)``. ``SelectKBest`` cannot pass
    groups, so it treats all rows as one recording; for fixed data bind them with
    ``functools.partial(spearman_relevance, groups=groups)``, or use :class:`SpearmanSelector`,
    which receives groups through ``fit`` (and metadata routing).

    Parameters
    ----------
    X : array-like of shape (n_samples, n_features)
        Candidate features, rows of a recording contiguous.
    y : array-like of shape (n_samples,)
        Target (driver torque).
    groups : array-like of shape (n_samples,), default=None
        Recording id of every row; ``None`` means one recording.

    Returns
    -------
    scores : ndarray of shape (n_features,)
        Mean absolute Spearman correlation over recordings, in [0, 1] (0 if the feature is
        constant in every recording).
    pvalues : ndarray of shape (n_features,)
        Per-recording two-sided p-values (those of :func:`scipy.stats.spearmanr`) combined with
        Fisher's method (:func:`scipy.stats.combine_pvalues`): the test of "no monotonic
        relation in any recording". 1 where the feature is constant everywhere.

    Examples
    --------
    >>> import numpy as np
    >>> from skhmmgmr.feature_selection import spearman_relevance
    >>> X = np.array([[1.0, 3.0], [2.0, 1.0], [3.0, 2.0], [1.0, 1.0], [2.0, 3.0], [3.0, 2.0]])
    >>> y = np.array([0.1, 0.2, 0.3, 1.1, 1.2, 1.3])
    >>> scores, pvalues = spearman_relevance(X, y, groups=[0, 0, 0, 1, 1, 1])
    >>> scores.round(2)
    array([1. , 0.5])
    """
    X = np.asarray(X, dtype=float)
    y = np.asarray(y, dtype=float).ravel()
    if X.ndim != 2 or len(X) != len(y):
        raise ValueError(f"X must be 2-D with one row per target value; got {X.shape}, {y.shape}")
    recordings = as_recordings(groups, len(X), min_length=3)
    n_features = X.shape[1]
    rho = np.full((len(recordings), n_features), np.nan)
    pvalue = np.full((len(recordings), n_features), np.nan)
    for i, (_, rows) in enumerate(recordings.slices()):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # constant columns: NaN, handled below
            result = stats.spearmanr(np.column_stack([X[rows], y[rows]]))
        r = np.atleast_2d(result.statistic)
        p = np.atleast_2d(result.pvalue)
        rho[i] = r[-1, :-1] if r.shape[0] > 1 else r.ravel()[:1]
        pvalue[i] = p[-1, :-1] if p.shape[0] > 1 else p.ravel()[:1]
    valid = np.isfinite(rho)
    scores = np.where(valid.any(axis=0), np.nanmean(np.where(valid, np.abs(rho), np.nan), 0), 0.0)
    combined = np.ones(n_features)
    for j in range(n_features):
        p = pvalue[valid[:, j], j]
        if p.size == 1:
            combined[j] = p[0]
        elif p.size > 1:
            combined[j] = stats.combine_pvalues(np.clip(p, 1e-300, 1.0), method="fisher").pvalue
    return scores, combined


class SpearmanSelector(SelectorMixin, BaseEstimator):
    """Keep the ``k`` features with the strongest mean absolute Spearman correlation.

    The filter of the thesis (method 1): correlations are taken per recording and averaged (see
    :func:`spearman_relevance`). ``fit`` requests ``groups`` through metadata routing by
    default, so inside a :class:`~sklearn.pipeline.Pipeline` or a search the recording ids
    reach it without ``set_fit_request``.

    Parameters
    ----------
    k : int or "all", default=10
        Number of features to keep (the thesis keeps 10).

    Attributes
    ----------
    scores_ : ndarray of shape (n_features,)
        Mean absolute Spearman correlation over recordings.
    pvalues_ : ndarray of shape (n_features,)
        Fisher-combined p-values.
    ranking_ : ndarray of shape (n_features,)
        Rank of every feature, 1 = strongest.
    n_features_in_ : int
    feature_names_in_ : ndarray of shape (n_features,)
        When ``X`` has string column names.

    Examples
    --------
    >>> import numpy as np
    >>> from skhmmgmr.feature_selection import SpearmanSelector
    >>> rng = np.random.default_rng(0)
    >>> X = rng.normal(size=(60, 3))
    >>> y = X[:, 2] + 0.1 * rng.normal(size=60)
    >>> SpearmanSelector(k=1).fit(X, y, groups=np.repeat([0, 1], 30)).get_support()
    array([False, False,  True])
    """

    _parameter_constraints = {
        "k": [StrOptions({"all"}), Interval(Integral, 0, None, closed="left")],
    }
    __metadata_request__fit = {"groups": True}

    def __init__(self, k=10):
        self.k = k

    @_fit_context(prefer_skip_nested_validation=True)
    def fit(self, X, y, groups=None):
        """Compute the per-recording correlations.

        Parameters
        ----------
        X : array-like of shape (n_samples, n_features)
        y : array-like of shape (n_samples,)
        groups : array-like of shape (n_samples,), default=None
            Recording id of every row; ``None`` means one recording.

        Returns
        -------
        self : SpearmanSelector
        """
        X, y = validate_data(self, X, y, y_numeric=True, dtype=float)
        if self.k != "all" and self.k > X.shape[1]:
            raise ValueError(f"k={self.k} is more than the {X.shape[1]} features")
        self.scores_, self.pvalues_ = spearman_relevance(X, y, groups=groups)
        order = np.argsort(-self.scores_, kind="stable")
        self.ranking_ = np.empty(len(order), dtype=int)
        self.ranking_[order] = np.arange(1, len(order) + 1)
        return self

    def _get_support_mask(self):
        check_is_fitted(self)
        if self.k == "all":
            return np.ones(self.n_features_in_, dtype=bool)
        return self.ranking_ <= self.k


# --------------------------------------------------------------------------------------------
# Exhaustive wrapper
# --------------------------------------------------------------------------------------------


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
    estimator : estimator, default=None
        Regressor with ``fit(X, y, groups=...)`` and ``predict(X, groups=...)``; ``None`` means
        ``HMMGMRRegressor(n_states=2, random_state=0)`` (the thesis' K=2, seeded so that subsets
        differ by their features only).
    max_features : int, default=None
        Largest subset size; ``None`` means all features (``2**n - 1`` subsets).
    min_features : int, default=1
        Smallest subset size.
    cv : int, splitter or iterable, default=5
        Training/validation split(s) of the recordings. An int means ``GroupKFold(cv)``; the
        thesis' fixed validation set is a ``PredefinedSplit`` (0 on validation rows, -1 on
        training rows). Every recording may be validated in one split only.
    accuracy_weight, smoothness_weight : float, default=0.5
        Trade-off used to choose the selected subset.
    sampling_period : float
        Seconds between two rows, for the smoothness. Required.
    n_jobs : int, default=None
        Parallel fits through joblib (any backend, e.g. ``joblib.parallel_backend("dask")``).
    memory : str or joblib.Memory, default=None
        Cache of every (subset, split) evaluation: a repeated or interrupted search resumes
        from it without refitting.
    verbose : int, default=0
        Show a progress bar when positive.

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
        **RecordingSelector._common_constraints,
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
    ):
        self.estimator = estimator
        self.max_features = max_features
        self.min_features = min_features
        self.cv = cv
        self.accuracy_weight = accuracy_weight
        self.smoothness_weight = smoothness_weight
        self.sampling_period = sampling_period
        self.n_jobs = n_jobs
        self.memory = memory
        self.verbose = verbose

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
        self.results_ = self._evaluate(X, y, groups, splits, subsets, "feature subsets")
        best = self.best_subsets(self._trade_off, per_recording=False)
        self.subset_ = best["subset"].iloc[0]
        self.support_ = np.isin(self._names(), self.subset_)
        return self

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


# --------------------------------------------------------------------------------------------
# Sequential forward wrapper
# --------------------------------------------------------------------------------------------


class ForwardFeatureSelector(RecordingSelector):
    """Method 2 of the thesis: sequential forward selection with the 1% stopping rule.

    Starting from the empty set, the feature whose addition gives the lowest performance score
    is added, until the best addition improves the score by no more than ``tol`` (relative) or
    ``max_features`` are selected. Models are fitted on the training recordings of every
    ``cv`` split and judged on the validation recordings; each distinct subset is fitted once
    and shared by all paths.

    The score of a path is the performance score with the D.5 normalisation frozen on the
    first step: on every recording each term is divided by its sum over the single-feature
    models (all candidates), so that scores along a path stay comparable while it grows.

    Parameters
    ----------
    estimator : estimator, default=None
        As in :class:`ExhaustiveFeatureSelector` (default a seeded K=2 HMM-GMR).
    mode : {"average", "per_recording"}, default="average"
        ``"average"``: one path on the score averaged over the validation recordings.
        ``"per_recording"``: one path per validation recording, as in the thesis; the selected
        subset is then the features in the final subsets of at least half of the recordings
        (the most frequent feature if none is).
    tol : float, default=0.01
        Stop when the best addition improves the score by no more than this fraction.
    max_features : int, default=None
        Largest subset size; ``None`` means no limit.
    trade_offs : str or list, default=None
        Further trade-offs for which paths are traced (for feature relevance); the
        trade-off of ``accuracy_weight``/``smoothness_weight`` is always traced.
    cv, accuracy_weight, smoothness_weight, sampling_period, n_jobs, memory, verbose
        As in :class:`ExhaustiveFeatureSelector`.

    Attributes
    ----------
    paths_ : pandas.DataFrame
        One row per step of every path: ``trade_off``, ``path`` ("average" or the recording
        id), ``step``, ``feature`` (tried for addition), ``subset``, ``performance_score``,
        ``gain`` (relative improvement), ``accepted``.
    results_ : pandas.DataFrame
        Metrics of every evaluated subset on every validation recording (as in
        :class:`ExhaustiveFeatureSelector`).
    subset_ : tuple of str
    support_ : ndarray of shape (n_features,)

    Examples
    --------
    >>> import numpy as np
    >>> from sklearn.model_selection import PredefinedSplit
    >>> from skhmmgmr.feature_selection import ForwardFeatureSelector
    >>> rng = np.random.default_rng(0)
    >>> X = np.cumsum(rng.normal(scale=0.1, size=(400, 3)), axis=0)
    >>> y = 2 * X[:, 0] + 0.01 * rng.normal(size=400)
    >>> groups = np.repeat([0, 1, 2, 3], 100)
    >>> cv = PredefinedSplit(np.where(groups >= 2, 0, -1))
    >>> ForwardFeatureSelector(cv=cv, sampling_period=0.1).fit(X, y, groups=groups).subset_
    ('x0',)
    """

    _parameter_constraints = {
        **RecordingSelector._common_constraints,
        "mode": [StrOptions({"average", "per_recording"})],
        "tol": [Interval(Real, 0, None, closed="left")],
        "max_features": [Interval(Integral, 1, None, closed="left"), None],
        "trade_offs": [str, list, tuple, None],
    }

    def __init__(
        self,
        estimator=None,
        *,
        mode="average",
        tol=0.01,
        max_features=None,
        trade_offs=None,
        cv=5,
        accuracy_weight=0.5,
        smoothness_weight=0.5,
        sampling_period=None,
        n_jobs=None,
        memory=None,
        verbose=0,
    ):
        self.estimator = estimator
        self.mode = mode
        self.tol = tol
        self.max_features = max_features
        self.trade_offs = trade_offs
        self.cv = cv
        self.accuracy_weight = accuracy_weight
        self.smoothness_weight = smoothness_weight
        self.sampling_period = sampling_period
        self.n_jobs = n_jobs
        self.memory = memory
        self.verbose = verbose

    @_fit_context(prefer_skip_nested_validation=False)
    def fit(self, X, y, groups=None):
        """Trace the forward paths.

        Parameters
        ----------
        X : array-like of shape (n_samples, n_features)
        y : array-like of shape (n_samples,)
        groups : array-like of shape (n_samples,), default=None
            Recording id of every row.

        Returns
        -------
        self : ForwardFeatureSelector
        """
        X, y, groups, splits = self._validate_search(X, y, groups)
        n_features = X.shape[1]
        max_features = n_features if self.max_features is None else self.max_features
        own = parse_trade_offs(self._trade_off)[0]
        extra = [] if self.trade_offs is None else parse_trade_offs(self.trade_offs)
        weights = {label: (w1, w2) for label, w1, w2 in [own, *extra]}

        recordings = pd.unique(np.concatenate([groups[val] for _, val in splits]))
        scores, tables = FrozenScores(recordings), []

        def evaluate(subsets):
            missing = scores.missing(subsets)
            if missing:
                tables.append(self._evaluate(X, y, groups, splits, missing, "forward step"))
                scores.add(missing, tables[-1])

        singles = [(j,) for j in range(n_features)]
        evaluate(singles)
        scores.freeze(singles)

        path_ids = ["average"] if self.mode == "average" else list(range(len(recordings)))
        paths = {}
        for label in weights:
            for path_id in path_ids:
                positions = slice(None) if path_id == "average" else [path_id]
                path = ForwardPath(n_features, tol=self.tol, max_features=max_features)
                paths[label, path_id] = (path, scores.scorer(*weights[label], positions))
        while any(path.active for path, _ in paths.values()):
            active = [(path, fn) for path, fn in paths.values() if path.active]
            evaluate([s for path, _ in active for s in path.candidates()])
            for path, score_of in active:
                path.step(score_of)

        names = self._names()
        self.paths_ = paths_table(
            {key: path for key, (path, _) in paths.items()}, names, recordings
        )
        self.results_ = pd.concat(tables, ignore_index=True)
        self.subset_ = self._chosen_subset(own[0])
        self.support_ = np.isin(names, self.subset_)
        return self

    def best_subsets(self, trade_off=None):
        """Final subset of every path traced for the trade-off(s).

        Parameters
        ----------
        trade_off : str, pair or list of those, default=None
            Traced trade-off(s); ``None`` means that of ``accuracy_weight`` and
            ``smoothness_weight``.

        Returns
        -------
        best : pandas.DataFrame
            One row per (trade-off, path) with ``recording`` (the path), ``subset``,
            ``n_features`` and ``performance_score``.
        """
        check_is_fitted(self, "paths_")
        labels = labels_of(self._trade_off if trade_off is None else trade_off)
        missing = [lab for lab in labels if lab not in set(self.paths_["trade_off"])]
        if missing:
            raise ValueError(
                f"no forward path was traced for trade-off(s) {missing}; add them to "
                "trade_offs and refit"
            )
        accepted = self.paths_[self.paths_["accepted"] & self.paths_["trade_off"].isin(labels)]
        final = accepted.groupby(["trade_off", "path"], sort=False).tail(1)
        best = final.rename(columns={"path": "recording"})[
            ["trade_off", "recording", "subset", "performance_score"]
        ].reset_index(drop=True)
        best.insert(3, "n_features", best["subset"].map(len))
        order = {label: i for i, label in enumerate(labels)}
        return best.sort_values("trade_off", key=lambda s: s.map(order), kind="stable")

    def _chosen_subset(self, label):
        final = self.best_subsets(label)
        if self.mode == "average":
            return final["subset"].iloc[0]
        counts = pd.Series([f for subset in final["subset"] for f in subset]).value_counts()
        chosen = set(counts.index[counts >= len(final) / 2]) or {counts.index[0]}
        return tuple(name for name in self._names() if name in chosen)
