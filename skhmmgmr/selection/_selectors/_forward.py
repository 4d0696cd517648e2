"""The forward wrapper of the thesis (Section IV-B, method 2): sequential forward selection
with the 1% rule, on the average over validation recordings or one path per recording.

Splits as in the exhaustive wrapper (:mod:`._exhaustive`); the greedy paths and their frozen
scores are :mod:`._forward_paths`. Public through :mod:`skhmmgmr.feature_selection`.
"""

from numbers import Integral, Real

import numpy as np
import pandas as pd
from sklearn.utils.validation import check_is_fitted

from ..._core._compat import Interval, StrOptions, _fit_context
from ..._core._docstrings import fill_shared_parameters
from ...metrics._table import parse_trade_offs
from .._search import _screening
from .._search._decisions import (
    THESIS_SHARES,
    count_thresholds,
    possible_winners,
    units_to_confirm,
)
from .._search._score_tables import labels_of
from .._search.base import RecordingSelector
from ._forward_paths import ForwardPath, FrozenScores, paths_table, settled_prefix


@fill_shared_parameters
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
    {estimator}
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
    {search parameters}

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
        **RecordingSelector._parameter_constraints,
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
        self.mode = mode
        self.tol = tol
        self.max_features = max_features
        self.trade_offs = trade_offs

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
        scores, tables, exact = FrozenScores(recordings), [], set()

        def evaluate(subsets, in_full=False):
            missing = scores.missing(subsets) if not in_full else subsets
            if missing:
                table = self._evaluate_subsets(
                    X, y, groups, splits, missing, "forward step", in_full=in_full
                )
                tables.append(table)
                scores.add(missing, table)
                if "screened" not in table:
                    exact.update(missing)
                else:
                    by_subset = table.groupby("subset", sort=False)["screened"].any()
                    pairs = zip(missing, by_subset, strict=True)
                    exact.update(s for s, screened in pairs if not screened)

        def confirm(active):
            # every step of a path being confirmed reads full fits: its possible best
            # options (those a screened score within the bound could make the best)
            while True:
                needed = set()
                for path, score_of in active:
                    options = path.candidates()
                    values = [score_of(s) for s in options]
                    flags = [s in exact for s in options]
                    possible = possible_winners(values, flags, tolerance)
                    needed.update(s for s, p in zip(options, possible, strict=True) if p)
                todo = sorted(needed - exact)
                if not todo:
                    return
                evaluate(todo, in_full=True)

        def trace(entries, confirmed):
            while any(path.active for path, _ in entries):
                active = [(path, fn) for path, fn in entries if path.active]
                evaluate([s for path, _ in active for s in path.candidates()])
                if confirmed:
                    confirm(active)
                for path, score_of in active:
                    path.step(score_of)

        with self._searching(X, y, groups, splits):
            tolerance = _screening.SCREENING_ERROR
            searched_fast = getattr(self, "_fast_search", None) is not None
            fast = searched_fast and tolerance is not None
            singles = [(j,) for j in range(n_features)]
            # the fast search fits the single features in full: every score is divided by
            # their sums, and a single feature's marginal of the joint model is a poor model
            evaluate(singles, in_full=searched_fast)
            scores.freeze(singles)

            path_ids = ["average"] if self.mode == "average" else list(range(len(recordings)))

            def new_path(label, path_id):
                positions = slice(None) if path_id == "average" else [path_id]
                path = ForwardPath(n_features, tol=self.tol, max_features=max_features)
                return path, scores.scorer(*weights[label], positions)

            paths = {(label, i): new_path(label, i) for label in weights for i in path_ids}
            trace(list(paths.values()), confirmed=False)
            while fast:  # retrace, confirmed, the paths that can move a relevance decision
                chosen = self._paths_to_confirm(paths, own[0], exact, tolerance)
                if not chosen:
                    break
                for key in chosen:
                    paths[key] = new_path(*key)
                trace([paths[key] for key in chosen], confirmed=True)

        names = self._names()
        self.paths_ = paths_table(
            {key: path for key, (path, _) in paths.items()}, names, recordings
        )
        results = pd.concat(tables, ignore_index=True)
        if "screened" in results:  # a subset fitted in full replaces its screened rows
            confirmed = results.loc[~results["screened"], "subset"]
            results = results[~(results["screened"] & results["subset"].isin(set(confirmed)))]
        self.results_ = results.reset_index(drop=True)
        self.subset_ = self._chosen_subset(own[0])
        self.support_ = np.isin(names, self.subset_)
        return self

    def _paths_to_confirm(self, paths, own_label, exact, tolerance):
        """The paths to retrace with every step confirmed, so that each trade-off's
        relevance decisions (:mod:`.._search._decisions`; at the selector's own trade-off
        also the per-recording mode's half of the paths) are settled by the bound."""
        n_features = self.n_features_in_
        chosen = set()
        for label in dict.fromkeys(label for label, _ in paths):
            keys = [key for key in paths if key[0] == label]
            shape = (len(keys), n_features)
            always, ever = np.zeros(shape, dtype=bool), np.zeros(shape, dtype=bool)
            point = np.zeros(shape, dtype=bool)
            for u, key in enumerate(keys):
                path, score_of = paths[key]
                settled, certain = settled_prefix(path, score_of, exact, tolerance)
                point[u, list(path.selected)] = True
                always[u, list(settled)] = True
                ever[u] = point[u] if certain else True
            shares = tuple(THESIS_SHARES.values())
            if label == own_label and self.mode == "per_recording":
                shares = (*shares, 0.5)
            units = units_to_confirm(always, ever, point, count_thresholds(len(keys), shares))
            chosen.update(keys[u] for u in units)
        return chosen

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
