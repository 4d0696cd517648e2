"""Evaluations of the selection: fit a model per split and score it on every validation recording.

One evaluation = fit a clone of the estimator on the training recordings of a split (optionally on
a subset of the columns, with changed parameters) and score its causal estimate on every
validation recording of that split. Evaluations run through joblib (any backend, including
dask's), can be cached with :class:`joblib.Memory`, are shared between the steps of one framework
run (:func:`shared_evaluations`), and come back as one tidy table with one row per (model,
validation recording).
"""

import contextvars
import functools
import hashlib
import numbers
import os
import shutil
import tempfile
import warnings
from contextlib import contextmanager
from importlib import metadata
from pathlib import Path

import joblib
import numpy as np
import pandas as pd
from sklearn.base import clone
from sklearn.exceptions import ConvergenceWarning
from sklearn.model_selection import GroupKFold, check_cv
from sklearn.utils.validation import check_memory
from threadpoolctl import threadpool_limits

from ..._core._progress import progress_bar
from ..._core._validation import check_sampling_period
from ..._version import __version__
from ...cluster._scatter import dask_client, scatter_once
from ...metrics._scores import evaluate_recordings

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


def shared_evaluation_store():
    """The evaluations shared in the current :func:`shared_evaluations` block, else None.

    A dict ``{(context, subset names): table}`` that the searches read and add to.
    """
    return _SHARED_EVALUATIONS.get()


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


# The package's folder (skhmmgmr/): the source of every module an evaluation runs.
PACKAGE_FOLDER = Path(__file__).resolve().parents[2]
# Libraries whose numerics an evaluation calls: their versions are part of the cache key.
_NUMERIC_LIBRARIES = ("numpy", "scipy", "scikit-learn", "numba")


@functools.cache
def _installed_code():
    """SHA-256 of the package's Python source (an edited development install keeps its
    version number) and the versions of the numerical libraries, read once per process."""
    digest = hashlib.sha256()
    for path in sorted(PACKAGE_FOLDER.rglob("*.py")):
        digest.update(str(path.relative_to(PACKAGE_FOLDER)).encode())
        digest.update(path.read_bytes())
    versions = {name: metadata.version(name) for name in _NUMERIC_LIBRARIES}
    return {"source": digest.hexdigest(), **versions}


def code_version():
    """What a cached evaluation depends on besides its arguments.

    :class:`joblib.Memory` keys a result by the arguments and the source of the cached
    function only, not by the code that function calls: the package's version and source and
    the versions of the numerical libraries go in as an argument, so that another version
    recomputes instead of serving stale results.
    """
    return {"skhmmgmr": __version__, **_installed_code()}


def _fit_and_evaluate(
    folds, data_token, fold, estimator, columns, params, sampling_period, with_bic, code_version
):
    # ``folds`` is left out of the cache key; ``data_token`` stands for it. ``code_version``
    # is only there for the key (see code_version()).
    return fitted_and_scored(folds, fold, estimator, columns, params, sampling_period, with_bic)[1]


def fitted_and_scored(folds, fold, estimator, columns, params, sampling_period, with_bic=False):
    """``(model, table)``: a clone of ``estimator`` with ``params`` fitted on the columns
    ``columns`` of the training rows of split ``fold`` (of :func:`fold_arrays`), and its
    table of every validation recording (with the BIC of the training rows when
    ``with_bic``): one evaluation of the full search."""
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
    return model, table


def longest_first(estimator, models):
    """Indices of ``models`` (list of (columns, params)) from the costliest to fit to the
    cheapest, ties in their order.

    An E-step costs about ``K (D + 1)^2 + K^2`` per row for K states over D columns. Workers
    that take the longest fits first finish together; in the given order (subsets by size,
    K upwards) the last long fit ran alone while the other workers were idle (the forward
    search left 17 worker-seconds idle in 142 s, measured on 2 workers, issue #27).
    """
    defaults = estimator.get_params()

    def cost(columns, params):
        merged = {**defaults, **params}
        states = [v for k, v in merged.items() if k == "n_states" or k.endswith("__n_states")]
        n_states = states[0] if states and isinstance(states[0], numbers.Integral) else 1
        return n_states * (len(columns) + 1) ** 2 + n_states**2

    costs = [cost(columns, params) for columns, params in models]
    return sorted(range(len(models)), key=lambda i: -costs[i])


def fold_arrays(X, y, codes, splits):
    """Training and validation arrays of every split, sliced once for all models.

    Column-major: every model takes a subset of the columns, which is then a copy of
    contiguous columns (1.2 ms for 5 of 18 columns of 504,000 rows) instead of a gather from
    every row (17 ms, measured on a memory map; issue #27).
    """
    return [
        (
            np.asfortranarray(X[train]),
            y[train],
            codes[train],
            np.asfortranarray(X[val]),
            y[val],
            codes[val],
        )
        for train, val in splits
    ]


@contextmanager
def shared_with_workers(folds, n_jobs):
    """The fold arrays as read-only memory maps when models are fitted in other processes.

    joblib would otherwise hash and copy the data for every model it sends to a worker; a
    memory-mapped array is sent as its file name. The folder is deleted when the block ends,
    also on an exception or ``KeyboardInterrupt`` (joblib then kills its workers). For a run
    that is killed outright (SIGTERM, SIGKILL) it is also registered with the resource
    tracker of joblib's process backend (loky), a process that outlives the run as it does
    for joblib's own memory-mapping folder: the tracker deletes it when the killed process and
    its workers are gone (idle workers exit after joblib's ``idle_worker_timeout``, 300 s).
    Under joblib's dask backend the arrays are scattered to the workers once instead
    (:mod:`skhmmgmr.cluster._scatter`).
    """
    client = dask_client()
    if client is not None:
        yield scatter_once(client, folds)
        return
    if n_jobs in (None, 1):
        yield folds
        return
    folder = tempfile.mkdtemp(prefix="skhmmgmr-")
    untrack = None
    try:
        untrack = _track_for_cleanup(folder)
        path = os.path.join(folder, "folds.joblib")
        joblib.dump(folds, path)
        yield joblib.load(path, mmap_mode="r")
    finally:
        shutil.rmtree(folder, ignore_errors=True)
        # A folder that could not be deleted now (a memory map still open on Windows) is
        # left to the tracker.
        if untrack is not None and not os.path.exists(folder):
            untrack()


def _track_for_cleanup(folder):
    """Register ``folder`` with loky's resource tracker; return the function that
    unregisters it."""
    try:
        from joblib.externals.loky.backend import resource_tracker
    except ImportError:  # a joblib without its process backend: no worker outlives the run
        return lambda: None
    resource_tracker.register(folder, "folder")
    return lambda: resource_tracker.unregister(folder, "folder")


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
    if check_sampling_period(sampling_period) is None:
        raise ValueError(
            "give sampling_period (seconds between rows): every model is scored on its smoothness"
        )
    memory = check_memory(memory)
    token = None
    if getattr(memory, "location", None) is not None:
        token = joblib.hash((X, y, groups, [(t, v) for t, v in splits]))
    task = memory.cache(_fit_and_evaluate, ignore=["folds"])
    version = code_version() if token is not None else None
    estimator = clone(estimator)
    # Recordings travel as integer codes: string ids would be pickled for every model and
    # re-encoded by every fit.
    codes, recording_ids = pd.factorize(np.asarray(groups), sort=False)
    tasks = [
        (model_id, fold)
        for model_id in longest_first(estimator, models)
        for fold in range(len(splits))
    ]
    with shared_with_workers(fold_arrays(X, y, codes, splits), n_jobs) as folds:
        jobs = (
            joblib.delayed(task)(
                folds=folds,
                data_token=token,
                fold=fold,
                estimator=estimator,
                columns=tuple(int(c) for c in models[model_id][0]),
                params=dict(models[model_id][1]),
                sampling_period=sampling_period,
                with_bic=with_bic,
                code_version=version,
            )
            for model_id, fold in tasks
        )
        parallel = joblib.Parallel(n_jobs=n_jobs, return_as="generator")
        # The models are small: BLAS threads on them only spin (as OpenMP's would in the
        # k-means fallback to scikit-learn), and the parallelism is over models (joblib
        # workers get their own limits).
        with threadpool_limits(limits=1):
            tables = list(
                progress_bar(parallel(jobs), total=len(tasks), desc=desc, disable=not verbose)
            )
    if not tables:
        return pd.DataFrame(columns=["model", "fold", "recording", "n_samples", *METRICS])
    in_order = sorted(zip(tasks, tables, strict=True), key=lambda item: item[0])
    for (model_id, _), table in in_order:
        table.insert(0, "model", model_id)
    table = pd.concat([table for _, table in in_order], ignore_index=True)
    table["recording"] = recording_ids[table["recording"].to_numpy(dtype=int)]
    return table
