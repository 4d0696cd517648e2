"""The base of the wrapper selectors: what a selector that searches over recordings shares.

:class:`RecordingSelector` (and its mixin :class:`RecordingSearchMixin`) validate the search's
inputs, evaluate subsets through :func:`~skhmmgmr._search._evaluation.evaluate_models` and give the
``SelectorMixin`` support mask. :mod:`skhmmgmr.selection` is the orchestrator that runs the
selectors of the thesis' framework in turn.
"""

import numbers

import joblib
import numpy as np
import pandas as pd
from sklearn.base import BaseEstimator, clone
from sklearn.feature_selection import SelectorMixin
from sklearn.utils.validation import check_is_fitted, validate_data

from .._core._compat import HasMethods, Interval
from .._core._panel import align_target, read_layout, recordings_of
from .._core._pickled import PickleVersionMixin
from .._core._validation import check_finite, check_target_finite, column_names_of
from ..estimator import HMMGMRRegressor
from ._evaluation import check_recording_splits, evaluate_models, shared_evaluation_store


def default_estimator():
    # A seeded K=2 model: subsets must differ by their features, not by their initialisation.
    return HMMGMRRegressor(n_states=2, random_state=0)


def input_feature_names(fitted):
    """The names of a fitted selector's input columns, ``x0, x1, ...`` when it saw none."""
    names = getattr(fitted, "feature_names_in_", None)
    if names is None:
        return np.asarray([f"x{i}" for i in range(fitted.n_features_in_)], dtype=object)
    return np.asarray(names, dtype=object)


def _evaluation_context(estimator, y, groups, splits, sampling_period):
    """What a shared evaluation depends on besides the feature names, as one hash.

    The recording ids enter as integer codes and their distinct values: joblib hashes an
    object array of ids by pickling every string (about 1 s for 756,000 rows, once per
    forward step, while every worker waited; issue #27).
    """
    codes, ids = pd.factorize(groups, sort=False)
    return joblib.hash((clone(estimator), y, codes, list(ids), splits, sampling_period))


class RecordingSearchMixin:
    """Parameters and helpers shared by the selectors that fit one model per candidate."""

    # Recording ids make the data sequences: requested by default, like HMMGMRRegressor.
    __metadata_request__fit = {"groups": True}

    _common_constraints = {
        "estimator": [HasMethods(["fit", "predict"]), None],
        "cv": ["cv_object"],
        "accuracy_weight": [Interval(numbers.Real, 0, None, closed="left")],
        "smoothness_weight": [Interval(numbers.Real, 0, None, closed="left")],
        "sampling_period": [Interval(numbers.Real, 0, None, closed="neither"), None],
        "n_jobs": [numbers.Integral, None],
        "memory": [None, str, HasMethods(["cache"])],
        "verbose": ["verbose"],
    }

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

    def _evaluate(self, X, y, groups, splits, subsets, desc):
        estimator = default_estimator() if self.estimator is None else self.estimator
        names = self._names()
        subset_names = [tuple(names[list(s)]) for s in subsets]
        shared = shared_evaluation_store()
        context = known = None
        if shared is not None and hasattr(self, "feature_names_in_"):
            context = _evaluation_context(estimator, y, groups, splits, self.sampling_period)
            known = {
                i: shared[context, key]
                for i, key in enumerate(subset_names)
                if (context, key) in shared
            }
        todo = [i for i in range(len(subsets)) if not known or i not in known]
        table = evaluate_models(
            estimator,
            X,
            y,
            groups,
            splits,
            [(subsets[i], {}) for i in todo],
            sampling_period=self.sampling_period,
            n_jobs=self.n_jobs,
            memory=self.memory,
            verbose=self.verbose,
            desc=desc,
        )
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

    def _get_support_mask(self):
        check_is_fitted(self, "support_")
        return self.support_

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
