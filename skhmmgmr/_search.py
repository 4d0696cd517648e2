"""Shared machinery of the feature and state selection.

One evaluation = fit a clone of the estimator on the training recordings of a split (optionally on
a subset of the columns, with changed parameters) and score its causal estimate on every
validation recording of that split. Evaluations run through joblib (any backend, including
dask's), can be cached with :class:`joblib.Memory`, and come back as one tidy table with one row
per (model, validation recording).
"""

import contextvars
import numbers
import os
import tempfile
import warnings
from contextlib import contextmanager

import joblib
import numpy as np
import pandas as pd
from scipy import stats
from sklearn.base import BaseEstimator, clone
from sklearn.exceptions import ConvergenceWarning
from sklearn.feature_selection import SelectorMixin
from sklearn.model_selection import GroupKFold, check_cv
from sklearn.utils.validation import check_is_fitted, check_memory, validate_data
from threadpoolctl import threadpool_limits
from tqdm.auto import tqdm

from ._compat import HasMethods, Interval
from ._metrics_table import parse_trade_offs
from .datasets._schema import FEATURE_NAMES, RECORDING, SPLIT, TIME
from .estimator import HMMGMRRegressor
from .metrics import evaluate_recordings, normalize_performance

METRICS = ["rmse", "accuracy", "smoothness"]

# Evaluations shared between the search steps of one framework run (see shared_evaluations).
_SHARED_EVALUATIONS = contextvars.ContextVar("skhmmgmr_shared_evaluations", default=None)


@contextmanager
def shared_evaluations():
    """Within this block, a feature subset evaluated by one search step is not refitted by
    another.

    A model is reused when the estimator, the training and validation recordings (``y``,
    ``groups`` and the splits), the sampling period and the subset's feature *names*, in the
    same order, are the same; the feature columns themselves are identified by their names,
    so the block must only hold searches over one data table (as in
    :func:`~skhmmgmr.select_parameters`, whose forward step meets many subsets of the top
    features that its exhaustive step has already evaluated).
    """
    token = _SHARED_EVALUATIONS.set({})
    try:
        yield
    finally:
        _SHARED_EVALUATIONS.reset(token)


# --------------------------------------------------------------------------------------------
# Splits and evaluation
# --------------------------------------------------------------------------------------------


def check_recording_splits(cv, X, y, groups):
    """Return a list of ``(train, validation)`` row indices, each recording validated once.

    An integer means ``GroupKFold(cv)``. The thesis' fixed validation set is
    ``PredefinedSplit(test_fold)`` with ``test_fold`` 0 on validation rows and -1 elsewhere.
    """
    if isinstance(cv, numbers.Integral):
        if groups is None:
            raise ValueError(
                f"cv={cv} splits the recordings with GroupKFold and needs groups (one recording "
                "id per row); give groups, or a splitter such as PredefinedSplit"
            )
        cv = GroupKFold(n_splits=cv)
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="The groups parameter is ignored")
        splits = [
            (np.asarray(train), np.asarray(val))
            for train, val in check_cv(cv).split(X, y, groups=groups)
        ]
    if not splits:
        raise ValueError("cv produced no split")
    groups = np.zeros(len(y), dtype=int) if groups is None else np.asarray(groups)
    seen = {}
    for fold, (train, val) in enumerate(splits):
        if len(train) == 0 or len(val) == 0:
            raise ValueError(f"split {fold} has no training or no validation rows")
        for rec in pd.unique(groups[val]):
            if rec in seen:
                raise ValueError(
                    f"recording {rec!r} is validated in splits {seen[rec]} and {fold}; every "
                    "validation recording must be scored by exactly one model per candidate "
                    "(use GroupKFold or PredefinedSplit, not a shuffling splitter)"
                )
            seen[rec] = fold
    return splits


def _fit_and_evaluate(
    folds, data_token, fold, estimator, columns, params, sampling_period, with_bic
):
    # ``folds`` is left out of the cache key; ``data_token`` stands for it.
    X_train, y_train, groups_train, X_val, y_val, groups_val = folds[fold]
    columns = list(columns)
    model = clone(estimator).set_params(**params)
    X_fit = X_train[:, columns]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        model.fit(X_fit, y_train, groups=groups_train)
    table = evaluate_recordings(
        y_val,
        model.predict(X_val[:, columns], groups=groups_val),
        groups=groups_val,
        sampling_period=sampling_period,
    )
    table.insert(0, "fold", fold)
    table["converged"] = bool(getattr(model, "converged_", True))
    if with_bic:
        table["bic"] = model.bic(X_fit, y_train, groups=groups_train)
    return table


def _fold_arrays(X, y, codes, splits):
    """Training and validation arrays of every split, sliced once for all models."""
    return [(X[train], y[train], codes[train], X[val], y[val], codes[val]) for train, val in splits]


@contextmanager
def _shared_with_workers(folds, n_jobs):
    """The fold arrays as read-only memory maps when models are fitted in other processes.

    joblib would otherwise hash and copy the data for every model it sends to a worker; a
    memory-mapped array is sent as its file name.
    """
    if n_jobs in (None, 1):
        yield folds
        return
    with tempfile.TemporaryDirectory(prefix="skhmmgmr-", ignore_cleanup_errors=True) as folder:
        path = os.path.join(folder, "folds.joblib")
        joblib.dump(folds, path)
        yield joblib.load(path, mmap_mode="r")


def evaluate_models(
    estimator,
    X,
    y,
    groups,
    splits,
    models,
    *,
    sampling_period,
    with_bic=False,
    n_jobs=None,
    memory=None,
    verbose=0,
    desc="models",
):
    """Fit and evaluate every model on every split.

    Parameters
    ----------
    models : list of (columns, params)
        Column indices of ``X`` and estimator parameters of every model.

    Returns
    -------
    table : pandas.DataFrame
        Columns ``model`` (index in ``models``), ``fold``, ``recording``, ``n_samples``,
        ``rmse``, ``accuracy``, ``smoothness``, ``converged`` (and ``bic`` of the training
        recordings when ``with_bic``).
    """
    memory = check_memory(memory)
    token = None
    if getattr(memory, "location", None) is not None:
        token = joblib.hash((X, y, groups, [(t, v) for t, v in splits]))
    task = memory.cache(_fit_and_evaluate, ignore=["folds"])
    estimator = clone(estimator)
    # Recordings travel as integer codes: string ids would be pickled for every model and
    # re-encoded by every fit.
    codes, recording_ids = pd.factorize(np.asarray(groups), sort=False)
    n_tasks = len(models) * len(splits)
    with _shared_with_workers(_fold_arrays(X, y, codes, splits), n_jobs) as folds:
        jobs = (
            joblib.delayed(task)(
                folds=folds,
                data_token=token,
                fold=fold,
                estimator=estimator,
                columns=tuple(int(c) for c in columns),
                params=dict(params),
                sampling_period=sampling_period,
                with_bic=with_bic,
            )
            for columns, params in models
            for fold in range(len(splits))
        )
        parallel = joblib.Parallel(n_jobs=n_jobs, return_as="generator")
        # The models are small: BLAS and OpenMP threads (k-means) on them only spin, and
        # the parallelism is over models (joblib workers get their own limits).
        with threadpool_limits(limits=1):
            tables = list(tqdm(parallel(jobs), total=n_tasks, desc=desc, disable=not verbose))
    if not tables:
        return pd.DataFrame(columns=["model", "fold", "recording", "n_samples", *METRICS])
    model_ids = np.repeat(np.arange(len(models)), len(splits))
    for model_id, table in zip(model_ids, tables, strict=True):
        table.insert(0, "model", model_id)
    table = pd.concat(tables, ignore_index=True)
    table["recording"] = recording_ids[table["recording"].to_numpy(dtype=int)]
    return table


# --------------------------------------------------------------------------------------------
# Tables of compared models
# --------------------------------------------------------------------------------------------


def rescore_table(results, key, trade_offs):
    """D.5-normalised performance scores of ``results`` for every trade-off.

    The models compared are the distinct values of the ``key`` column; every other column of
    ``results`` is kept. No model is refitted.
    """
    codes, _ = pd.factorize(results[key])
    table = results.assign(_model=codes)
    scores = normalize_performance(table, weights=trade_offs, model="_model")
    kept = table
    merged = scores.merge(kept, on=["_model", "recording"], how="left", sort=False)
    front = ["trade_off", "accuracy_weight", "smoothness_weight"]
    rest = [c for c in kept.columns if c not in ("_model", "recording")]
    tail = ["accuracy_term", "smoothness_term", "performance_score"]
    return merged[[*front, *rest, "recording", *tail]]


def best_per_recording(scores, key, *, tie_breaker=None):
    """Row of the lowest performance score per (trade-off, recording), ties to ``tie_breaker``."""
    order = ["performance_score", tie_breaker] if tie_breaker else ["performance_score"]
    best = scores.sort_values(order, kind="stable").drop_duplicates(["trade_off", "recording"])
    position = scores.groupby(["trade_off", "recording"], sort=False).ngroup()
    return (
        best.assign(_pos=position.loc[best.index])
        .sort_values("_pos")
        .drop(columns="_pos")
        .reset_index(drop=True)
    )


def best_on_average(scores, key, *, tie_breaker=None):
    """Model with the lowest mean performance score over recordings, per trade-off."""
    columns = [key, tie_breaker] if tie_breaker else [key]
    means = scores.groupby(["trade_off", *columns], sort=False).agg(
        performance_score=("performance_score", "mean"),
        accuracy=("accuracy", "mean"),
        smoothness=("smoothness", "mean"),
    )
    means = means.reset_index()
    order = ["performance_score", tie_breaker] if tie_breaker else ["performance_score"]
    best = means.sort_values(order, kind="stable").drop_duplicates("trade_off")
    labels = list(dict.fromkeys(scores["trade_off"]))
    return best.set_index("trade_off").loc[labels].reset_index()


def labels_of(trade_offs):
    return [label for label, _, _ in parse_trade_offs(trade_offs)]


def relative_gain(previous, new):
    """Relative improvement ``(previous - new) / previous`` of a lower-is-better score."""
    if not np.isfinite(previous):
        return np.inf
    if previous <= 0:
        return 0.0
    return (previous - new) / previous


def one_way_anova(table, *, by, values):
    """One-way ANOVA (:func:`scipy.stats.f_oneway`) of each ``values`` column across ``by``.

    Each group holds the rows (recordings) of one level of ``by``; the test asks whether the
    group means differ. Returns one row per value column: ``F``, ``pvalue``, ``n_groups`` and
    ``groups`` (tuple of the levels entered, in order of appearance).
    """
    rows = []
    for column in [values] if isinstance(values, str) else values:
        parts = [(level, g[column].to_numpy(float)) for level, g in table.groupby(by, sort=False)]
        parts = [(level, s) for level, s in parts if s.size]
        samples = [s for _, s in parts]
        statistic, pvalue = np.nan, np.nan
        if len(samples) > 1 and any(np.ptp(s) > 0 for s in samples):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                statistic, pvalue = stats.f_oneway(*samples)
        rows.append(
            {
                "metric": column,
                "F": float(statistic),
                "pvalue": float(pvalue),
                "n_groups": len(samples),
                "groups": tuple(level for level, _ in parts),
            }
        )
    return pd.DataFrame(rows)


class ForwardPath:
    """One greedy forward path: add the feature with the lowest score while it gains > tol."""

    def __init__(self, n_candidates, *, tol, max_features):
        self.n_candidates = n_candidates
        self.tol = tol
        self.max_features = max_features
        self.selected = ()
        self.score = np.inf
        self.active = True
        self.history = []

    def candidates(self):
        return [
            tuple(sorted((*self.selected, j)))
            for j in range(self.n_candidates)
            if j not in self.selected
        ]

    def step(self, score_of):
        options = [
            (score_of(tuple(sorted((*self.selected, j)))), j)
            for j in range(self.n_candidates)
            if j not in self.selected
        ]
        best_score, feature = min(options)
        gain = relative_gain(self.score, best_score)
        accepted = gain > self.tol
        self.history.append(
            {
                "step": len(self.history) + 1,
                "feature": feature,
                "subset": tuple(sorted((*self.selected, feature))),
                "performance_score": best_score,
                "gain": gain,
                "accepted": accepted,
            }
        )
        if accepted:
            self.selected = (*self.selected, feature)
            self.score = best_score
        done = len(self.selected) >= min(self.max_features, self.n_candidates)
        self.active = accepted and not done


class FrozenScores:
    """Performance scores of evaluated subsets with the D.5 sums frozen on a reference set.

    Each term is divided, per recording, by its sum over the reference subsets, so that scores
    of subsets evaluated later stay comparable with earlier ones.
    """

    def __init__(self, recordings):
        self.recordings = recordings
        self.terms = {}

    def missing(self, subsets):
        return [s for s in dict.fromkeys(subsets) if s not in self.terms]

    def add(self, subsets, table):
        parts = table.groupby("subset", sort=False)
        for subset, (_, part) in zip(subsets, parts, strict=True):
            part = part.set_index("recording").loc[self.recordings]
            self.terms[subset] = (
                np.abs(100.0 - part["accuracy"].to_numpy()),
                np.abs(part["smoothness"].to_numpy()),
            )

    def freeze(self, reference):
        totals = np.sum([self.terms[s] for s in reference], axis=0)
        self.scales = np.where(totals > 0, totals, np.inf)

    def scorer(self, accuracy_weight, smoothness_weight, positions):
        """Function subset -> mean score over the recordings at ``positions``."""

        def score_of(subset):
            loss, rough = self.terms[subset]
            per_recording = (
                accuracy_weight * loss / self.scales[0] + smoothness_weight * rough / self.scales[1]
            )
            return float(np.mean(per_recording[positions]))

        return score_of


def paths_table(paths, names, recordings):
    """One row per step of every forward path ``{(trade_off, path_id): ForwardPath}``."""
    rows = []
    for (label, path_id), path in paths.items():
        name = "average" if path_id == "average" else recordings[path_id]
        for entry in path.history:
            rows.append(
                {
                    "trade_off": label,
                    "path": name,
                    **entry,
                    "feature": names[entry["feature"]],
                    "subset": tuple(names[list(entry["subset"])]),
                }
            )
    return pd.DataFrame(rows)


# --------------------------------------------------------------------------------------------
# Data of the one-call framework
# --------------------------------------------------------------------------------------------


def split_recordings_table(data, split, candidate_features, target):
    """Features, target, recording ids and split of every row of a tidy table or arrays."""
    if isinstance(data, pd.DataFrame):
        if candidate_features is None:
            candidate_features = [c for c in FEATURE_NAMES if c in data.columns]
            if not candidate_features:
                meta = {RECORDING, SPLIT, TIME, target, "driver", "setting"}
                candidate_features = [
                    c
                    for c in data.columns
                    if c not in meta and pd.api.types.is_numeric_dtype(data[c])
                ]
        X = data[list(candidate_features)].reset_index(drop=True)
        y = data[target].to_numpy(dtype=float)
        groups = data[RECORDING].to_numpy()
        split = data[SPLIT].to_numpy() if split is None else split
    else:
        X, y, groups = data
        if split is None:
            raise ValueError("give split (per row or recording -> split) with (X, y, groups)")
        if not isinstance(X, pd.DataFrame):
            names = candidate_features or [f"x{i}" for i in range(np.shape(X)[1])]
            X = pd.DataFrame(np.asarray(X, dtype=float), columns=list(names))
        X = X.reset_index(drop=True)
        y, groups = np.asarray(y, dtype=float), np.asarray(groups)
    if isinstance(split, dict):
        split = np.asarray([split[g] for g in groups])
    split = np.asarray(split)
    for name in ("train", "validation", "test"):
        if not np.any(split == name):
            raise ValueError(f"no {name!r} recordings in split")
    return X, y, groups, split


def sampling_period_of(data, sampling_period):
    """The given sampling period, else the median time step of the ``time`` column."""
    if sampling_period is not None:
        return sampling_period
    if isinstance(data, pd.DataFrame) and TIME in data.columns:
        steps = data.groupby(RECORDING, sort=False)[TIME].diff().dropna()
        return float(steps.median())
    raise ValueError("give sampling_period (seconds between rows)")


# --------------------------------------------------------------------------------------------
# Base class of the wrapper selectors
# --------------------------------------------------------------------------------------------


def default_estimator():
    # A seeded K=2 model: subsets must differ by their features, not by their initialisation.
    return HMMGMRRegressor(n_states=2, random_state=0)


def input_feature_names(fitted):
    """The names of a fitted selector's input columns, ``x0, x1, ...`` when it saw none."""
    names = getattr(fitted, "feature_names_in_", None)
    if names is None:
        return np.asarray([f"x{i}" for i in range(fitted.n_features_in_)], dtype=object)
    return np.asarray(names, dtype=object)


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
        if self.sampling_period is None:
            raise ValueError(
                f"{type(self).__name__} needs sampling_period (seconds between rows) for the "
                "smoothness metric"
            )
        if self.accuracy_weight == 0 and self.smoothness_weight == 0:
            raise ValueError("accuracy_weight and smoothness_weight are both 0")
        X, y = validate_data(self, X, y, y_numeric=True, dtype=float, ensure_all_finite=False)
        if groups is not None and len(groups) != len(X):
            raise ValueError(f"groups has {len(groups)} rows but X has {len(X)}")
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
        shared = _SHARED_EVALUATIONS.get()
        context = known = None
        if shared is not None and hasattr(self, "feature_names_in_"):
            context = joblib.hash((clone(estimator), y, groups, splits, self.sampling_period))
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


class RecordingSelector(RecordingSearchMixin, SelectorMixin, BaseEstimator):
    """Feature selector over recordings (fit on training, judge on validation recordings)."""
