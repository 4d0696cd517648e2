"""The fast search: every model screened from a warm start, and what a decision reads fitted as
the full search fits it.

The full search (:mod:`._evaluation`) fits every model from its own k-means start until EM
converges. The fast one (``search="fast"``) starts each model from a model fitted already:

- **feature subsets** (the exhaustive and forward wrappers): per split, one joint model over
  all the selector's columns is fitted as the full search fits a model (it is the evaluation of
  the all-columns subset); every other subset is scored as the joint model's marginal over
  the subset's columns and the target (:func:`~skhmmgmr._hmm._em_start.marginal_start`, exact
  in the means and covariances), after a few EM iterations on the training columns
  standardised once per split: :data:`EXHAUSTIVE_ITERATIONS` in the exhaustive wrapper,
  :data:`SUBSET_ITERATIONS` elsewhere (none by default: a screened subset then costs the
  forward pass over its validation rows only); the forward wrapper fits its single features
  in full;
- **numbers of states** (the state selector): one chain per split grows K = 1 to the largest K
  by splitting a state (:func:`~skhmmgmr._hmm._em_start.split_state`) and running at most
  :data:`STATE_ITERATIONS` EM iterations after each split; then the numbers of states that the
  selector's decision reads (its ``settle`` function) are fitted as the full search fits them
  (:func:`~._evaluation.evaluate_models`), until the decision reads no screened model.

A screened model is read out and scored as the full search scores a fitted one (the causal GMR
estimate of every validation recording, :func:`~skhmmgmr.metrics.evaluate_recordings`), and
the table has the full search's columns. The fast search serves a plain
:class:`~skhmmgmr.HMMGMRRegressor` with complete data (``missing_values="error"``), no read-out
(``output_smoothing=None``) and one output (:func:`serves`); any other estimator is searched
in full. Screened models run in parallel as the full search's do (joblib, dask), a batch of
models per task, the costliest first, and are cached in ``memory`` too.
"""

from contextlib import ExitStack, suppress
from dataclasses import dataclass

import joblib
import numpy as np
import pandas as pd
from sklearn.base import clone
from sklearn.utils.validation import check_memory
from threadpoolctl import threadpool_limits
from tqdm.auto import tqdm

from ..._core._sequences import as_recordings
from ..._hmm._em import fit_hmm
from ..._hmm._em_data import Columns
from ..._hmm._em_start import marginal_start, refined, split_state
from ..._hmm._fitted import FittedHMMGMR, Standardization
from ..._hmm._gaussian import NotPositiveDefiniteError
from ..._hmm._gmr import condition_on_inputs
from ..._hmm._gmr_scores import error_sums
from ...estimator import HMMGMRRegressor
from ._evaluation import (
    code_version,
    fitted_and_scored,
    fold_arrays,
    shared_with_workers,
)

#: The search strategies (``search``): the fast one (this module) and the full one.
SEARCHES = ("fast", "full")

#: EM iterations of a feature subset from the joint model's marginal (fewer when the
#: estimator's ``n_iter`` is smaller; 0: the marginal is scored as it is): the forward
#: wrapper's (and any other's but the exhaustive one). The forward wrapper fits its single
#: features in full in the fast search: they scale every score, and a single feature's
#: marginal of a joint model over many is a poor model (screened, a forward path on the
#: tests' data took an irrelevant feature first).
SUBSET_ITERATIONS = 0
#: The exhaustive wrapper's: every subset of the joint model's columns is screened and the
#: relevance reads each recording's best. Measured on the exhaustive stage at the thesis'
#: scale (issue #47, the selection page of the user guide): a screen with 0 iterations costs
#: 4 % of a full fit (25 ms against 0.58 s per subset, one process), with 2 iterations 23 %;
#: the per-recording best subsets and the exhaustive candidates that differ from the full
#: search's are 224 of 462 and 20 of 66 with 0 iterations, 195 and 14 with 2, while the full
#: search with another k-means seed differs from itself in 298 and 26.
EXHAUSTIVE_ITERATIONS = 0
#: EM iterations after every split of the state sweep's chain.
STATE_ITERATIONS = 3
#: When set (a share, e.g. 0.01): the bound of the relative error of a screened model's terms
#: (``|100 - accuracy|`` and the smoothness per validation recording, against the full
#: search's fit of the same model) under which the wrappers confirm, fitted in full, only
#: what can change a decision the framework reads (:mod:`._decisions`): in the exhaustive
#: wrapper the possible best subsets of the (trade-off, recording) pairs that can swing a
#: relevance count across a candidate threshold, and the possible best subsets on average; in
#: the forward wrapper the single features (every score is divided by their sums) and every
#: step of the paths that can swing such a count, retraced. Off (``None``): the decisions
#: read screened scores. At the thesis' scale the bound settles few decisions for many full
#: fits (``benchmarks/bench_framework.py --screening-error``, the selection page of the user
#: guide).
SCREENING_ERROR = None
#: Screened models per task: the per-task cost (reading the fold, a worker's start) is
#: spread over them, and the last tasks stay short.
BATCH_SIZE = 8


def serves(estimator, y):
    """Whether the fast search serves ``estimator`` on the target ``y``: a plain
    :class:`~skhmmgmr.HMMGMRRegressor` (not a subclass, whose fit may differ) with complete
    data, no read-out and one output."""
    return (
        type(estimator) is HMMGMRRegressor
        and estimator.missing_values == "error"
        and estimator.output_smoothing is None
        and np.ndim(y) == 1
    )


@dataclass(frozen=True)
class _EMSettings:
    """What the screened EM takes from the estimator (with a model's parameters)."""

    n_states: int
    n_iter: int
    tol: float
    reg_covar: float
    subset_iterations: int
    state_iterations: int

    @classmethod
    def of(cls, estimator, params, subset_iterations):
        merged = {**estimator.get_params(), **params}
        n_iter = merged["n_iter"]
        return cls(
            merged["n_states"],
            n_iter,
            merged["tol"],
            merged["reg_covar"],
            min(subset_iterations, n_iter),
            min(STATE_ITERATIONS, n_iter),
        )


def _standardised_fold(model, train, val):
    """The arrays a screened model reads, in the units of the fitted ``model`` (its
    standardisation): the training columns, the target and a row of ones as the EM engine
    holds them (C order, one row per column), the training recordings, the standardised
    validation inputs (column-major) and what scores them (the target's spread per
    validation recording)."""
    X_train, y_train, codes_train, X_val, y_val, codes_val = (*train, *val)
    scaling = model.model_.standardization
    center, scale = scaling.center, scaling.scale
    n_features = X_train.shape[1]
    values = np.empty((n_features + 2, X_train.shape[0]))
    values[:n_features] = ((X_train - center[:n_features]) / scale[:n_features]).T
    values[n_features] = (y_train - center[n_features]) / scale[n_features]
    values[n_features + 1] = 1.0
    val_recordings = _recordings(codes_val)
    spread = [np.std(y_val[rows]) for _, rows in val_recordings.slices()]
    return {
        "values": values,
        "train_codes": np.asarray(codes_train),
        "val_inputs": np.asfortranarray((X_val - center[:n_features]) / scale[:n_features]),
        "y_val": np.asarray(y_val, dtype=float),
        "val_codes": np.asarray(codes_val),
        "y_spread": np.asarray(spread),
        "center": center,
        "scale": scale,
    }


def _recordings(codes):
    return as_recordings(codes, len(codes))


def _scored(params, fold, columns, standardised, sampling_period):
    """The table of the screened model ``params`` (standardised units, over ``columns`` and
    the target) on every validation recording: the metrics of
    :func:`~skhmmgmr.metrics.evaluate_recordings` (RMSE, accuracy, smoothness) of its causal
    GMR estimate, from one compiled pass (:func:`~skhmmgmr._hmm._gmr_scores.error_sums`)."""
    n_features = standardised["values"].shape[0] - 2
    recordings = _recordings(standardised["val_codes"])
    gmr = condition_on_inputs(params.startprob, params.transmat, params.emissions, len(columns))
    sums = error_sums(
        standardised["val_inputs"],
        columns,
        recordings,
        gmr,
        standardised["y_val"],
        standardised["center"][n_features],
        standardised["scale"][n_features],
    )
    n_samples = np.asarray(recordings.lengths)
    rmse = np.sqrt(sums[:, 0] / n_samples)
    steps = n_samples - 1
    step_mean = sums[:, 1] / steps
    step_variance = np.maximum(sums[:, 2] / steps - step_mean**2, 0.0)
    return pd.DataFrame(
        {
            "fold": fold,
            "recording": recordings.ids,
            "n_samples": n_samples,
            "rmse": rmse,
            "accuracy": (1.0 - rmse / standardised["y_spread"]) * 100.0,
            "smoothness": np.sqrt(step_variance) / sampling_period,
        }
    )


def _bic(result, columns, standardised, n_rows):
    """BIC of the EM ``result`` on its ``n_rows`` training rows, in the data's units (as
    :meth:`~skhmmgmr.HMMGMRRegressor.bic` gives it)."""
    n_features = standardised["values"].shape[0] - 2
    dims = [*columns, n_features]
    params = result.parameters
    center, scale = standardised["center"][dims], standardised["scale"][dims]
    scaling = Standardization(center, scale, len(columns))
    model = FittedHMMGMR.from_standardized(
        params.startprob, params.transmat, params.emissions, scaling
    )
    log_likelihood = result.log_likelihood + scaling.log_jacobian(n_rows)
    return -2.0 * log_likelihood + model.n_parameters() * np.log(n_rows)


def _engine_columns(standardised, columns):
    """The engine's columns of ``columns`` and the target (a copy, C order)."""
    values = standardised["values"]
    n_features = values.shape[0] - 2
    rows = [*columns, n_features, n_features + 1]
    return Columns(np.ascontiguousarray(values[rows]), np.zeros(len(rows) - 1))


def _joint_fit(
    folds, data_token, fold, estimator, columns, params, sampling_period, with_bic, version
):
    """:func:`~._evaluation.fitted_and_scored`, with a cache key (``data_token`` stands for
    ``folds``, ``version`` for the code)."""
    return fitted_and_scored(folds, fold, estimator, columns, params, sampling_period, with_bic)


def _screen_subsets(arrays, data_token, fold, joint, batch, settings, sampling_period, version):
    """Tables of the feature subsets ``batch`` of split ``fold``, each from the marginal of
    the ``joint`` model (``data_token`` and ``version`` are only there for the cache key)."""
    standardised = arrays[fold]
    n_features = standardised["values"].shape[0] - 2
    recordings = _recordings(standardised["train_codes"])
    tables = []
    for columns in batch:
        params = marginal_start(joint, [*columns, n_features])
        if settings.subset_iterations > 0:
            # a state that collapses on these columns leaves the marginal, still a model
            with suppress(NotPositiveDefiniteError):
                params = refined(
                    _engine_columns(standardised, columns),
                    recordings,
                    params,
                    n_iter=settings.subset_iterations,
                    reg_covar=settings.reg_covar,
                )
        table = _scored(params, fold, columns, standardised, sampling_period)
        table["converged"] = False  # a fixed number of iterations, no convergence test
        tables.append(table)
    return tables


def _grow_states(arrays, data_token, fold, one, columns, ks, settings, sampling_period, version):
    """Tables of every K > 1 in ``ks`` of split ``fold``, with the BIC of the training rows: a
    chain grown from the one-state model ``one`` one split at a time (``data_token`` and
    ``version`` are only there for the cache key)."""
    standardised = arrays[fold]
    engine_columns = _engine_columns(standardised, columns)
    recordings = _recordings(standardised["train_codes"])
    n_rows = engine_columns.n_samples
    params, tables = one, {}
    for n_states in range(2, max(ks) + 1):
        result = fit_hmm(
            engine_columns,
            recordings,
            n_states,
            n_iter=settings.state_iterations,
            tol=settings.tol,
            reg_covar=settings.reg_covar,
            initial_parameters=split_state(params),
        )
        params = result.parameters
        if n_states in ks:
            table = _scored(params, fold, columns, standardised, sampling_period)
            table["converged"] = bool(result.converged)
            table["bic"] = _bic(result, columns, standardised, n_rows)
            tables[n_states] = table
    return tables


class FastSearch:
    """The fast search over the data of one selector's ``fit`` (a context manager: the data
    are shared with the workers while it is open).

    Parameters
    ----------
    estimator : HMMGMRRegressor
        The selector's estimator (see :func:`serves`).
    X, y, groups, splits
        As the full search takes them (:func:`~._evaluation.evaluate_models`).
    sampling_period, n_jobs, memory, verbose
        As the full search takes them.
    evaluate_in_full : callable
        ``evaluate_in_full(models, desc, with_bic=...)``: the table of ``models`` on this
        data fitted as the full search fits them (the selector's
        :func:`~._evaluation.evaluate_models`).
    subset_iterations : int, default=None
        EM iterations of a screened feature subset; ``None``: :data:`SUBSET_ITERATIONS`.
    """

    def __init__(
        self,
        estimator,
        X,
        y,
        groups,
        splits,
        *,
        sampling_period,
        n_jobs,
        memory,
        verbose,
        evaluate_in_full,
        subset_iterations=None,
    ):
        self.estimator = clone(estimator)
        if subset_iterations is None:
            subset_iterations = SUBSET_ITERATIONS
        self.subset_iterations = subset_iterations
        self.X, self.y, self.groups, self.splits = X, y, groups, splits
        self.sampling_period = sampling_period
        self.n_jobs, self.memory, self.verbose = n_jobs, check_memory(memory), verbose
        self.evaluate_in_full = evaluate_in_full
        self._stack = ExitStack()
        self._joints = {}
        self._arrays = None
        self._token = None
        if getattr(self.memory, "location", None) is not None:
            self._token = joblib.hash((X, y, groups, [(t, v) for t, v in splits], "fast"))
        self.codes, self.recording_ids = pd.factorize(np.asarray(groups), sort=False)

    def __enter__(self):
        return self

    def __exit__(self, *exc_info):
        self._stack.close()
        self._joints.clear()
        self._arrays = None

    # -- the joint models ----------------------------------------------------------------
    def _joint_models(self, params, desc, with_bic=False):
        """Per split: the joint model over all columns (fitted with ``params``) and its
        table (with the BIC when ``with_bic``), fitted once per ``params`` as the full search
        fits a model."""
        key = (tuple(sorted(params.items())), with_bic)
        if key not in self._joints:
            folds = fold_arrays(self.X, self.y, self.codes, self.splits)
            all_columns = tuple(range(self.X.shape[1]))
            task = self.memory.cache(_joint_fit, ignore=["folds"])
            version = code_version() if self._token is not None else None
            fitted = self._parallel(
                [
                    joblib.delayed(task)(
                        folds,
                        self._token,
                        fold,
                        self.estimator,
                        all_columns,
                        params,
                        self.sampling_period,
                        with_bic,
                        version,
                    )
                    for fold in range(len(folds))
                ],
                f"{desc} (joint models)",
            )
            if self._arrays is None:
                arrays = [
                    _standardised_fold(model, fold[:3], fold[3:])
                    for model, fold in zip((m for m, _ in fitted), folds, strict=True)
                ]
                self._arrays = self._stack.enter_context(shared_with_workers(arrays, self.n_jobs))
            self._joints[key] = fitted
        return self._joints[key]

    # -- evaluations -----------------------------------------------------------------------
    def evaluate(self, models, desc, *, with_bic=False, settle=None):
        """The table of ``models`` (``(columns, params)``), as
        :func:`~._evaluation.evaluate_models` returns it: screened feature subsets when the
        models share their parameters, a screened state sweep when they share their columns
        and differ by ``n_states`` only, else the full search.

        ``settle``, when given, is called with the table of the screened and exact models
        (a column ``model``) and returns the indices of the models whose values the caller's
        decision reads; those are fitted as the full search fits them, until it returns none
        that is still screened.
        """
        if not models:
            return self._full(models, desc, with_bic)
        columns = {tuple(int(c) for c in m[0]) for m in models}
        params = [dict(m[1]) for m in models]
        if all(p == params[0] for p in params) and not with_bic:
            table = self._subsets(models, params[0], desc)
        elif len(columns) == 1 and all(set(p) == {"n_states"} for p in params):
            table = self._states(models, desc, with_bic)
        else:
            return self._full(models, desc, with_bic)
        if settle is not None:
            table = self._settle(table, models, desc, with_bic, settle)
        return table

    def _full(self, models, desc, with_bic, ids=None):
        table = self.evaluate_in_full(models, desc, with_bic=with_bic)
        if ids is not None:
            table["model"] = [ids[i] for i in table["model"]]
        return table

    def _settle(self, table, models, desc, with_bic, settle):
        while True:
            screened = set(table.loc[table["screened"], "model"])
            todo = sorted({int(i) for i in settle(table)} & screened)
            if not todo:
                return table
            fitted = self._full([models[i] for i in todo], f"{desc} (settled)", with_bic, todo)
            fitted["screened"] = False
            table = pd.concat([table[~table["model"].isin(todo)], fitted], ignore_index=True)
            table = table.sort_values(["model", "fold"], kind="stable", ignore_index=True)

    def _subsets(self, models, params, desc):
        joints = self._joint_models(params, desc)
        all_columns = tuple(range(self.X.shape[1]))
        settings = _EMSettings.of(self.estimator, params, self.subset_iterations)
        order = sorted(
            range(len(models)), key=lambda i: -((len(models[i][0]) + 1) ** 2) * settings.n_states
        )
        batches = [order[i : i + BATCH_SIZE] for i in range(0, len(order), BATCH_SIZE)]
        task = self.memory.cache(_screen_subsets, ignore=["arrays"])
        version = code_version() if self._token is not None else None
        jobs, keys = [], []
        for fold, (joint, _) in enumerate(joints):
            parameters = joint.model_.hmm_parameters()
            for batch in batches:
                screened = [i for i in batch if tuple(models[i][0]) != all_columns]
                if screened:
                    columns = [tuple(int(c) for c in models[i][0]) for i in screened]
                    jobs.append(
                        joblib.delayed(task)(
                            self._arrays,
                            self._token,
                            fold,
                            parameters,
                            columns,
                            settings,
                            self.sampling_period,
                            version,
                        )
                    )
                    keys.append((fold, screened))
        results = self._parallel(jobs, desc)
        tables = {}
        for (fold, screened), batch_tables in zip(keys, results, strict=True):
            tables.update({(i, fold): t for i, t in zip(screened, batch_tables, strict=True)})
        exact = set()
        for i, (columns, _) in enumerate(models):
            if tuple(columns) == all_columns:
                for fold, (_, table) in enumerate(joints):
                    tables[i, fold] = table
                    exact.add((i, fold))
        return self._assembled(tables, exact)

    def _states(self, models, desc, with_bic):
        columns = tuple(int(c) for c in models[0][0])
        ks = [int(p["n_states"]) for _, p in models]
        # K = 1, fitted as the full search fits it, starts every chain
        joints = self._joint_models({"n_states": 1}, desc, with_bic=True)
        settings = _EMSettings.of(self.estimator, {}, self.subset_iterations)
        task = self.memory.cache(_grow_states, ignore=["arrays"])
        version = code_version() if self._token is not None else None
        jobs = [
            joblib.delayed(task)(
                self._arrays,
                self._token,
                fold,
                joint.model_.hmm_parameters(),
                columns,
                ks,
                settings,
                self.sampling_period,
                version,
            )
            for fold, (joint, _) in enumerate(joints)
        ]
        results = self._parallel(jobs, desc) if max(ks) > 1 else [{} for _ in jobs]
        tables, exact = {}, set()
        for fold, (chain, (_, one)) in enumerate(zip(results, joints, strict=True)):
            if 1 in ks:
                chain = {1: one, **chain}
                exact.add((ks.index(1), fold))
            tables.update({(ks.index(k), fold): table for k, table in chain.items()})
        table = self._assembled(tables, exact)
        return table if with_bic else table.drop(columns="bic")

    def _assembled(self, tables, exact=()):
        pieces = []
        for (model_id, fold), table in sorted(tables.items()):
            pieces.append(table.assign(model=model_id, screened=(model_id, fold) not in exact))
        table = pd.concat(pieces, ignore_index=True)
        table = table[["model", *[c for c in table.columns if c != "model"]]]
        table["recording"] = self.recording_ids[table["recording"].to_numpy(dtype=int)]
        return table

    def _parallel(self, jobs, desc):
        parallel = joblib.Parallel(n_jobs=self.n_jobs, return_as="generator")
        with threadpool_limits(limits=1):  # as in evaluate_models
            return list(tqdm(parallel(jobs), total=len(jobs), desc=desc, disable=not self.verbose))
