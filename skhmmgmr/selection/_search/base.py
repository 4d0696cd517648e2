"""The base of the selectors that search over recordings: what they share.

:class:`RecordingSearchMixin` defines the parameters every such selector takes (the estimator,
the splits, the trade-off, the sampling period, the jobs, the cache, the verbosity), validates
the search's inputs and is the selectors' one door to the evaluation of models
(:func:`~._evaluation.evaluate_models`, the full search, or :class:`~._screening.FastSearch`,
the fast one, by ``search``); :class:`RecordingSelector` adds ``SelectorMixin``'s support mask
for the feature selectors. :func:`read_search_inputs` is the one reader of a
selector's ``fit`` inputs.
"""

import numbers
from contextlib import contextmanager
from functools import partial

import joblib
import numpy as np
import pandas as pd
from sklearn.base import BaseEstimator, clone
from sklearn.feature_selection import SelectorMixin
from sklearn.utils.validation import check_is_fitted, validate_data

from ..._core._compat import HasMethods, StrOptions
from ..._core._docstrings import fill_shared_parameters
from ..._core._panel import align_target, read_layout, recordings_of
from ..._core._pickled import PickleVersionMixin
from ..._core._validation import check_finite, check_target_finite, column_names_of
from ...estimator import HMMGMRRegressor
from ...metrics._table import SAMPLING_PERIOD, WEIGHT
from ._evaluation import check_recording_splits, evaluate_models, shared_evaluation_store
from ._screening import SEARCHES, FastSearch, serves


def default_estimator():
    # A seeded K=2 model: subsets must differ by their features, not by their initialisation.
    return HMMGMRRegressor(n_states=2, random_state=0)


def input_feature_names(fitted):
    """The names of a fitted selector's input columns, ``x0, x1, ...`` when it saw none."""
    names = getattr(fitted, "feature_names_in_", None)
    if names is None:
        return np.asarray([f"x{i}" for i in range(fitted.n_features_in_)], dtype=object)
    return np.asarray(names, dtype=object)


def _evaluation_context(estimator, y, groups, splits, sampling_period, search=None):
    """What a shared evaluation depends on besides the feature names, as one hash.

    The recording ids enter as integer codes and their distinct values: joblib hashes an
    object array of ids by pickling every string (about 1 s for 756,000 rows, once per
    forward step, while every worker waited; issue #27). ``search``: ``None`` for the full
    search, else what names the fast search's screens (with their EM iterations per subset):
    a screened evaluation is shared with fast searches of the same iterations only.
    """
    codes, ids = pd.factorize(groups, sort=False)
    context = (clone(estimator), y, codes, list(ids), splits, sampling_period)
    return joblib.hash(context if search is None else (*context, search))


#: The constraints of the parameters every search takes: the selectors' (through
#: :class:`RecordingSearchMixin`) and the search functions' (:func:`search_constraints`); the
#: trade-off's and the sampling period's are the metrics'.
SEARCH_CONSTRAINTS = {
    "estimator": [HasMethods(["fit", "predict"]), None],
    "cv": ["cv_object"],
    "accuracy_weight": WEIGHT,
    "smoothness_weight": WEIGHT,
    "sampling_period": SAMPLING_PERIOD,
    "n_jobs": [numbers.Integral, None],
    "memory": [None, str, HasMethods(["cache"])],
    "verbose": ["verbose"],
    "search": [StrOptions(set(SEARCHES))],
}


def search_constraints(*names):
    """The constraints of the search parameters ``names``, for ``validate_params`` of a
    function that takes them as a selector does."""
    return {name: SEARCH_CONSTRAINTS[name] for name in names}


@fill_shared_parameters
class RecordingSearchMixin:
    """The parameters, checks and evaluations shared by the selectors that fit one model per
    candidate (a feature subset, a number of states) and judge it on validation recordings.

    The shared parameters are defined here once: their constraints, their storage in
    ``__init__`` and their description (the entries of ``_core/_docstrings.py`` that the lines
    ``{estimator}`` and ``{search parameters}`` of a docstring stand for, below and in every
    selector's). A selector adds its own parameters to
    ``_parameter_constraints`` and to ``__init__``, whose signature restates the shared
    ones (scikit-learn reads an estimator's parameters from that signature) and hands them
    to this ``__init__``.

    Parameters
    ----------
    {estimator}
    {search parameters}
    """

    # Recording ids make the data sequences: requested by default, like HMMGMRRegressor.
    __metadata_request__fit = {"groups": True}

    _parameter_constraints: dict = SEARCH_CONSTRAINTS

    def __init__(
        self,
        estimator=None,
        *,
        cv=5,
        accuracy_weight=0.5,
        smoothness_weight=0.5,
        sampling_period=None,
        n_jobs=None,
        memory=None,
        verbose=0,
        search="full",
    ):
        self.estimator = estimator
        self.cv = cv
        self.accuracy_weight = accuracy_weight
        self.smoothness_weight = smoothness_weight
        self.sampling_period = sampling_period
        self.n_jobs = n_jobs
        self.memory = memory
        self.verbose = verbose
        self.search = search

    def _validate_search(self, X, y, groups):
        # At least one training and one validation row.
        X, y, groups = read_search_inputs(self, X, y, groups, min_samples=2)
        if self.sampling_period is None:
            raise ValueError(
                f"{type(self).__name__} needs sampling_period (seconds between rows) for the "
                "smoothness metric"
            )
        if self.accuracy_weight == 0 and self.smoothness_weight == 0:
            raise ValueError("accuracy_weight and smoothness_weight are both 0")
        splits = check_recording_splits(self.cv, X, y, groups)
        groups = np.zeros(len(X), dtype=int) if groups is None else np.asarray(groups)
        return X, y, groups, splits

    @property
    def _trade_off(self):
        return (self.accuracy_weight, self.smoothness_weight)

    def _names(self):
        return input_feature_names(self)

    def _search_estimator(self):
        return default_estimator() if self.estimator is None else self.estimator

    @contextmanager
    def _searching(self, X, y, groups, splits):
        """The block of a ``fit`` whose evaluations take the search of ``search``: the fast
        one holds its data (shared with the workers) until the block ends."""
        estimator = self._search_estimator()
        if self.search != "fast" or not serves(estimator, y):
            self._fast_search = None
            try:
                yield
            finally:
                del self._fast_search
            return
        with FastSearch(
            estimator,
            X,
            y,
            groups,
            splits,
            sampling_period=self.sampling_period,
            n_jobs=self.n_jobs,
            memory=self.memory,
            verbose=self.verbose,
            evaluate_in_full=partial(self._evaluate_in_full, X, y, groups, splits),
            subset_iterations=self._subset_iterations(),
        ) as search:
            self._fast_search = search
            try:
                yield
            finally:
                del self._fast_search

    def _subset_iterations(self):
        """EM iterations of a feature subset screened by the fast search; ``None``: the
        fast search's default (:data:`~._screening.SUBSET_ITERATIONS`)."""
        return None

    def _evaluate_models(self, X, y, groups, splits, models, desc, *, with_bic=False, settle=None):
        """The selectors' one door to evaluation: every model, ``(columns, params)``, fitted
        on the training recordings of every split and scored on its validation recordings.

        In a :meth:`_searching` block of the fast search, :class:`~._screening.FastSearch`
        screens them, and fits as the full search does the models whose indices ``settle``
        (a function of the table, see :meth:`~._screening.FastSearch.evaluate`) returns;
        otherwise every model is fitted in full (:func:`~._evaluation.evaluate_models`).
        """
        search = getattr(self, "_fast_search", None)
        if search is not None:
            return search.evaluate(models, desc, with_bic=with_bic, settle=settle)
        return self._evaluate_in_full(X, y, groups, splits, models, desc, with_bic=with_bic)

    def _evaluate_in_full(self, X, y, groups, splits, models, desc, *, with_bic=False):
        """Every model fitted as the full search fits it (:func:`~._evaluation.evaluate_models`,
        the selector's settings); the fast search's door to its exact fits too."""
        return evaluate_models(
            self._search_estimator(),
            X,
            y,
            groups,
            splits,
            models,
            sampling_period=self.sampling_period,
            with_bic=with_bic,
            n_jobs=self.n_jobs,
            memory=self.memory,
            verbose=self.verbose,
            desc=desc,
        )

    def _evaluate_subsets(self, X, y, groups, splits, subsets, desc, settle=None, in_full=False):
        """The table of every feature subset (column indices) on every validation recording;
        in a :func:`~._evaluation.shared_evaluations` block, the subsets another search step
        evaluated are read, not refitted. ``settle``: as :meth:`_evaluate_models` takes it,
        on the table of the subsets evaluated here (``model`` indexes ``subsets``).
        ``in_full``: every subset fitted as the full search fits it, none read or screened."""
        names = self._names()
        subset_names = [tuple(names[list(s)]) for s in subsets]
        if in_full:  # the fast search's confirmation of screened subsets
            table = self._evaluate_in_full(
                X, y, groups, splits, [(s, {}) for s in subsets], desc
            ).assign(screened=False)
            table.insert(1, "subset", [subset_names[i] for i in table["model"]])
            table.insert(2, "n_features", [len(subsets[i]) for i in table["model"]])
            return table.drop(columns="model")
        shared = shared_evaluation_store()
        context = known = None
        if shared is not None and hasattr(self, "feature_names_in_"):
            fast = getattr(self, "_fast_search", None)
            search = None if fast is None else ("fast", fast.subset_iterations)
            context = _evaluation_context(
                self._search_estimator(), y, groups, splits, self.sampling_period, search
            )
            known = {
                i: shared[context, key]
                for i, key in enumerate(subset_names)
                if (context, key) in shared
            }
        todo = [i for i in range(len(subsets)) if not known or i not in known]
        settle_todo = None
        if settle is not None:
            position = {i: p for p, i in enumerate(todo)}

            def settle_todo(table):
                read = settle(table.assign(model=[todo[m] for m in table["model"]]))
                return [position[i] for i in read if i in position]

        models = [(subsets[i], {}) for i in todo]
        table = self._evaluate_models(X, y, groups, splits, models, desc, settle=settle_todo)
        if known is not None:
            table = self._merge_shared(table, todo, known, shared, context, subset_names)
        table.insert(1, "subset", [subset_names[i] for i in table["model"]])
        table.insert(2, "n_features", [len(subsets[i]) for i in table["model"]])
        return table.drop(columns="model")

    @staticmethod
    def _merge_shared(table, todo, known, shared, context, subset_names):
        """The new evaluations (``model`` indexes ``todo``) stored in ``shared``, and the
        table of all subsets in their order, the known ones included."""
        pieces = {todo[m]: piece.drop(columns="model") for m, piece in table.groupby("model")}
        shared.update({(context, subset_names[i]): piece for i, piece in pieces.items()})
        pieces.update(known)
        if not pieces:
            return table
        merged = pd.concat([pieces[i].assign(model=i) for i in sorted(pieces)], ignore_index=True)
        return merged[["model", *[c for c in merged.columns if c != "model"]]]

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        tags.target_tags.required = True
        return tags


def read_search_inputs(selector, X, y, groups, *, min_samples=1):
    """``(X, y, groups)`` of a selector's ``fit``, validated, in filter order: the one reader
    of the searches and SpearmanSelector.

    The recordings (and time order) come from ``groups`` or the index of ``X``, a panel's in
    one order for any row permutation (plain arrays keep their row order, which a
    ``PredefinedSplit`` indexes). Sparse ``X`` is refused (TypeError: the models fit dense
    rows); a non-finite target or input is refused here, not by the model of every split,
    naming the column and the recording by its id.
    """
    layout = read_layout(X, groups, canonical=True, reorder_groups=False)
    y = align_target(X, y, layout)
    X, y, groups = layout.to_filter_order(X), layout.to_filter_order(y), layout.handed_down()
    check_target_finite(y, groups)
    X, y = validate_data(
        selector,
        X,
        y,
        y_numeric=True,
        dtype=float,
        ensure_all_finite=False,
        ensure_min_samples=min_samples,
    )
    if groups is not None and len(groups) != len(X):
        raise ValueError(f"groups has {len(groups)} rows but X has {len(X)}")
    if not np.isfinite(X).all():
        check_finite(
            X,
            name="X",
            column_names=column_names_of(selector, X.shape[1]),
            recordings=recordings_of(groups, len(X)),
        )
    return X, y, groups


class RecordingSelector(PickleVersionMixin, RecordingSearchMixin, SelectorMixin, BaseEstimator):
    """Feature selector over recordings (fit on training, judge on validation recordings)."""

    def _get_support_mask(self):
        check_is_fitted(self, "support_")
        return self.support_
