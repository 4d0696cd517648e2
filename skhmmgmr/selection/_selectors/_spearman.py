"""The Spearman filter of the thesis (Section IV-B, Table II): absolute Spearman correlation
of every feature with the torque, averaged over recordings.

Public through :mod:`skhmmgmr.feature_selection`.
"""

import warnings
from numbers import Integral

import numpy as np
from scipy import stats
from sklearn.base import BaseEstimator
from sklearn.feature_selection import SelectorMixin
from sklearn.utils.validation import check_is_fitted

from ..._core._compat import Interval, StrOptions, _fit_context, validate_params
from ..._core._docstrings import fill_shared_parameters
from ..._core._panel import recordings_of
from ..._core._pickled import PickleVersionMixin
from ..._core._validation import check_dense, check_finite, check_target_finite
from .._search.base import read_search_inputs


@validate_params(
    {
        # sparse input reaches check_dense, whose message says what to do
        "X": ["array-like", "sparse matrix"],
        "y": ["array-like", "sparse matrix"],
        "groups": ["array-like", None],
    },
    prefer_skip_nested_validation=True,
)
@fill_shared_parameters
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
    {groups}

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
    check_dense(X, name="X", by="spearman_relevance")
    check_dense(y, name="y", by="spearman_relevance")
    check_target_finite(y, groups)
    names = [str(c) for c in X.columns] if hasattr(X, "columns") else None
    X = np.asarray(X, dtype=float)
    y = np.asarray(y, dtype=float).ravel()
    if X.ndim != 2 or len(X) != len(y):
        raise ValueError(f"X must be 2-D with one row per target value; got {X.shape}, {y.shape}")
    recordings = recordings_of(groups, len(X), min_length=3)
    # A NaN would silently drop its recording from the feature's average: refuse it.
    names = names or [f"x{j}" for j in range(X.shape[1])]
    check_finite(X, name="X", column_names=names, recordings=recordings)
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


class SpearmanSelector(PickleVersionMixin, SelectorMixin, BaseEstimator):
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
        X, y, groups = read_search_inputs(self, X, y, groups)
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
