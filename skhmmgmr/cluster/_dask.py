"""Running the package on a dask cluster (``pip install 'dask[distributed]'``).

Two ways past one machine:

- **the selection search on worker processes**: inside :func:`use_cluster` (or any
  ``joblib.parallel_config(backend="dask")``) the evaluations of
  :func:`~skhmmgmr.select_parameters`, the selectors and
  :class:`~skhmmgmr.StateSelector` are dask tasks (one model on one split each, batched by
  joblib when short); the recordings are scattered to every worker once per data table, never
  once per task (:mod:`skhmmgmr.cluster._scatter`). A worker that dies has its tasks rerun
  elsewhere; with ``memory=`` the finished evaluations are on disk, and a driver that is killed
  and started again resumes from them;
- **one model over recordings spread on the workers**: :func:`fit_on_cluster` runs the
  EM of one :class:`~skhmmgmr.HMMGMRRegressor` with the E-step on every partition where it
  lies and the M-step on the client, so that no machine holds all rows
  (:mod:`skhmmgmr.cluster._em`).
"""

import os
import warnings
from contextlib import contextmanager

import numpy as np
from sklearn.exceptions import ConvergenceWarning
from sklearn.utils import check_random_state

from .._core._compat import validate_parameter_constraints
from .._core._schema import TARGET
from .._core._validation import check_column_scales, check_enough_rows
from .._hmm._em import EMResult, HMMParameters, em_failure, m_step
from .._hmm._em_init import initial_centers
from .._hmm._emissions import emission_family
from .._hmm._fitted import FittedHMMGMR, Standardization
from .._hmm._gaussian import NotPositiveDefiniteError
from .._hmm._readout import fixed_decay
from ._em import (
    SpreadRows,
    load_partition,
    make_shard,
    partition_summary,
    shard_centre_statistics,
    shard_e_step,
    shard_totals,
    squared_deviations,
    standardization,
)
from ._scatter import dask_client

#: Environment of a worker process of one thread: one thread for BLAS, OpenMP and numba too
#: (dask's nanny sets the first ones; numba's compiled E-step would otherwise start a thread
#: per core in every worker). Give it to remote workers as well (see the user guide).
WORKER_ENVIRONMENT = {
    "OMP_NUM_THREADS": "1",
    "OPENBLAS_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1",
    "NUMBA_NUM_THREADS": "1",
}


@contextmanager
def use_cluster(scheduler=None):
    """Run the package's parallel work on a dask cluster within this block.

    Sets joblib's dask backend, so that every ``n_jobs`` search of the package
    (:func:`~skhmmgmr.select_parameters`, the selectors, :class:`~skhmmgmr.StateSelector`)
    runs its evaluations as tasks on the cluster's workers.

    Parameters
    ----------
    scheduler : str, distributed.Client, cluster object or None, default=None
        ``"local"`` or ``"local:N"``: a local cluster of N worker processes (one thread
        each, ``WORKER_ENVIRONMENT``; N defaults to the number of cores), closed with the
        block; a scheduler address
        (``"tcp://host:8786"``) or a cluster object (``LocalCluster``, ``SLURMCluster``,
        ``KubeCluster``...): a client connected to it for the block; a ``Client``: used as
        is; ``None``: the current default client.

    Yields
    ------
    client : distributed.Client

    Examples
    --------
    >>> from skhmmgmr.cluster import use_cluster
    >>> with use_cluster("local:2") as client:  # doctest: +SKIP
    ...     report = select_parameters(data)
    """
    import distributed
    import joblib

    cluster = client = None
    try:
        if isinstance(scheduler, distributed.Client):
            connected = scheduler
        elif scheduler is None:
            connected = distributed.get_client()
        else:
            if isinstance(scheduler, str) and scheduler.split(":")[0] == "local":
                n_workers = int(scheduler.split(":")[1]) if ":" in scheduler else None
                scheduler = cluster = distributed.LocalCluster(
                    n_workers=n_workers,
                    threads_per_worker=1,
                    processes=True,
                    dashboard_address=None,
                    env=WORKER_ENVIRONMENT,
                )
            connected = client = distributed.Client(scheduler, set_as_default=False)
        with joblib.parallel_config(backend="dask", client=connected):
            yield connected
    finally:
        if client is not None:
            client.close()
        if cluster is not None:
            cluster.close()


def _client_of(client):
    """The client given, else that of :func:`use_cluster`'s block, else dask's default."""
    if client is None:
        client = dask_client()
    if client is None:
        import distributed

        client = distributed.get_client()
    return client


def _partitions(client, data, features, target):
    """Futures of the partitions (:class:`~skhmmgmr.cluster._em.Partition`) on the workers.

    A parquet file's task is keyed by its path, modification time and size (read here): a
    file that changed is read again. When the client cannot see the file (it lies on the
    workers only), its task is never shared with another call."""
    if hasattr(data, "to_delayed"):  # a dask DataFrame
        import dask

        load = dask.delayed(load_partition, pure=True)
        name = "partition {} of the dask DataFrame".format
        parts = data.to_delayed()
        return client.compute(
            [load(part, features, target, name=name(i)) for i, part in enumerate(parts)]
        )
    futures = []
    for i, part in enumerate(data):
        if isinstance(part, (str, os.PathLike)):
            name, stamp = f"partition {i} (the file {str(part)!r})", _file_stamp(part)
        else:
            name, stamp = f"partition {i}", None
        pure = stamp is not None or not isinstance(part, (str, os.PathLike))
        futures.append(
            client.submit(load_partition, part, features, target, name=name, stamp=stamp, pure=pure)
        )
    return futures


def _file_stamp(path):
    """(modification time in ns, size, inode) of a file the client sees, else None."""
    try:
        stat = os.stat(path)
    except OSError:
        return None
    return stat.st_mtime_ns, stat.st_size, stat.st_ino


def _check_recordings_whole(summaries):
    seen = {}
    for index, summary in enumerate(summaries):
        for rec in summary["ids"]:
            if rec in seen:
                raise ValueError(
                    f"recording {rec!r} lies in partitions {seen[rec]} and {index}: partition "
                    "the data by recording (every recording whole in one partition)"
                )
            seen[rec] = index


def _merged(client, function, shards, *args):
    """``function(shard, *args)`` on every shard, merged in partition order."""
    futures = [client.submit(function, shard, *args, pure=False) for shard in shards]
    parts = client.gather(futures)
    total = parts[0]
    for part in parts[1:]:
        total = total.merge(part)
    return total


def _baum_welch(client, shards, n_samples, params, estimator):
    """EM from ``params`` as :func:`~skhmmgmr._hmm._em.baum_welch`, the E-step on the shards."""
    prior = type(params.emissions).prior_for(estimator.reg_covar, n_samples, params.n_states)
    history, objectives, converged, n_done = [], [], False, 0
    for iteration in range(1, estimator.n_iter + 1):
        n_done = iteration
        stats = _merged(client, shard_e_step, shards, params)
        objective = stats.log_likelihood + params.emissions.log_prior(prior)
        converged = bool(objectives) and abs(objective - objectives[-1]) < (
            estimator.tol * n_samples
        )
        history.append(stats.log_likelihood)
        objectives.append(objective)
        if converged:
            break
        params = m_step(stats, params, prior)
    else:
        history.append(_merged(client, shard_e_step, shards, params).log_likelihood)
        objectives.append(history[-1] + params.emissions.log_prior(prior))
    return EMResult(params, history[-1], history, n_done, converged, objectives[-1], objectives)


def _fit_spread(client, shards, counts, estimator):
    """The best of ``n_init`` EM runs, initialised as on one machine."""
    n_states, random_state = estimator.n_states, check_random_state(estimator.random_state)
    rows = SpreadRows(client, shards, counts)
    pooled = _merged(client, shard_totals, shards)
    family = emission_family(estimator.covariance_type)
    best = None
    for _ in range(estimator.n_init):
        centers = initial_centers(rows, n_states, estimator.init_params, random_state)
        moments = _merged(client, shard_centre_statistics, shards, centers)
        emissions = family.from_moments(moments, estimator.reg_covar, pooled)
        transmat = random_state.dirichlet(np.ones(n_states), size=n_states)
        params = HMMParameters(np.full(n_states, 1.0 / n_states), transmat, emissions)
        try:
            result = _baum_welch(client, shards, rows.n_samples, params, estimator)
        except NotPositiveDefiniteError as exc:
            raise em_failure(exc, estimator.reg_covar) from exc
        if best is None or result.objective > best.objective:
            best = result
    return best


def _check_supported(estimator):
    # the checks of ``fit``: fit_on_cluster never calls it
    validate_parameter_constraints(
        type(estimator)._parameter_constraints,
        estimator.get_params(deep=False),
        caller_name=type(estimator).__name__,
    )
    emission_family(estimator.covariance_type)
    if estimator.init_params == "random":
        raise ValueError(
            "init_params='random' draws one responsibility per row on the client; use "
            "'kmeans', 'k-means++' or 'random_from_data' with fit_on_cluster"
        )
    if estimator.missing_values != "error":
        raise ValueError("fit_on_cluster refuses missing values (missing_values='error')")
    if estimator.output_smoothing == "auto":
        raise ValueError(
            "fit_on_cluster takes output_smoothing=None or a finite time constant >= 0 in rows, "
            "not 'auto' (it would need every training estimate on the client)"
        )
    fixed_decay(estimator.output_smoothing)  # refuses the values fit refuses


def fit_on_cluster(estimator, data, *, features, target=TARGET, client=None):
    """Fit an :class:`~skhmmgmr.HMMGMRRegressor` on recordings spread over dask workers.

    Every EM iteration runs the E-step on every partition where it lies and sums the
    sufficient statistics; the M-step runs on the client. The initialisation (k-means on an
    evenly spaced sample of at most 100,000 rows, gathered to the client), the standardisation
    and the EM are those of :meth:`HMMGMRRegressor.fit <skhmmgmr.HMMGMRRegressor.fit>` on the
    partitions' rows in partition order: the fitted parameters are the same up to round-off.

    Parameters
    ----------
    estimator : HMMGMRRegressor
        Fitted in place (its parameters are read; ``init_params="random"`` and missing values
        are refused).
    data : dask DataFrame or list of str, path or pandas DataFrame
        The recordings, one row per sample with a ``recording`` column (and ``time``, checked
        to increase, when present); every recording whole in one partition (a dask DataFrame's
        partition, a parquet file or a DataFrame of the list), its rows in time order. Empty
        partitions (such as those of a filtered dask DataFrame) are left out. A parquet file
        that changed since an earlier fit is read again (its task is keyed by the file's
        modification time and size). A faulty partition (a missing column, text in a column,
        a file that is not parquet) is named in the error.
    features : list of str
        Input columns, in the model's order.
    target : str, default="driver_torque"
        Output column.
    client : distributed.Client, default=None
        The cluster's client; ``None`` means that of the enclosing :func:`use_cluster` block,
        else dask's default client.

    Returns
    -------
    estimator : HMMGMRRegressor
        The estimator, fitted, as after ``fit``.

    Examples
    --------
    >>> from skhmmgmr import HMMGMRRegressor
    >>> from skhmmgmr.cluster import fit_on_cluster, use_cluster
    >>> files = ["drivers/part-0.parquet", "drivers/part-1.parquet"]
    >>> with use_cluster("local:2") as client:  # doctest: +SKIP
    ...     model = fit_on_cluster(HMMGMRRegressor(n_states=5), files, features=["a", "b"])
    """
    _check_supported(estimator)
    client, features = _client_of(client), list(features)
    names = [*features, target]
    partitions = _partitions(client, data, features, target)
    summaries = client.gather([client.submit(partition_summary, p) for p in partitions])
    kept = [i for i, summary in enumerate(summaries) if summary["n_rows"]]
    if not kept:
        raise ValueError(f"every one of the {len(summaries)} partition(s) of data is empty")
    partitions, summaries = [partitions[i] for i in kept], [summaries[i] for i in kept]
    _check_recordings_whole(summaries)
    counts = [summary["n_rows"] for summary in summaries]
    check_enough_rows(sum(counts), estimator.n_states, len(names))
    mean = sum(summary["sums"] for summary in summaries) / sum(counts)
    deviations = client.gather([client.submit(squared_deviations, p, mean) for p in partitions])
    center, scale = standardization(summaries, deviations)
    check_column_scales(scale, names)
    shards = [client.submit(make_shard, p, center, scale, estimator.n_states) for p in partitions]
    del partitions  # the raw rows leave the workers once the shards exist
    result = _fit_spread(client, shards, counts, estimator)
    if not result.converged:
        warnings.warn(
            f"EM did not converge in n_iter={estimator.n_iter} iterations (tol={estimator.tol})",
            ConvergenceWarning,
            stacklevel=2,
        )
    params = result.parameters
    estimator.n_features_in_ = len(features)
    estimator.feature_names_in_ = np.asarray(features, dtype=object)
    estimator.n_outputs_ = 1
    estimator.longest_recording_ = max(summary["longest"] for summary in summaries)
    estimator.model_ = FittedHMMGMR.from_standardized(
        params.startprob,
        params.transmat,
        params.emissions,
        Standardization(center, scale, len(features)),
        scalar_output=True,
        feature_names=estimator.feature_names_in_,
        output_decay=[fixed_decay(estimator.output_smoothing)],
    )
    jacobian = estimator.model_.standardization.log_jacobian(sum(counts))
    estimator.n_iter_, estimator.converged_ = result.n_iter, result.converged
    estimator.log_likelihood_ = result.log_likelihood + jacobian
    estimator.log_likelihood_history_ = np.asarray(result.history) + jacobian
    estimator.penalized_log_likelihood_ = result.objective + jacobian
    estimator.penalized_log_likelihood_history_ = np.asarray(result.objective_history) + jacobian
    return estimator
