"""The EM of one model over recordings spread on dask workers: what runs where.

The rows stay on the workers, in partitions that each hold whole recordings. The client holds
the parameters and sums what the workers send back, all of a size independent of the rows:

1. every worker reads its partition (:func:`load_partition`: a pandas frame or a parquet
   file, one row per sample, the recordings contiguous) into one array ``(n_rows, n_columns)``
   of the inputs and the target, and returns per-column counts, sums and extremes; the client
   derives the column means, then the sums of squared deviations about them
   (:func:`squared_deviations`), hence the standardisation of the single-machine fit (two
   passes, the same constant-column rule);
2. every worker builds its standardised columns and E-step data (:func:`make_shard`, an
   :class:`~skhmmgmr._hmm._em_data.EStepData`, kept on the worker between iterations);
3. initialisation as on one machine: the k-means sample (evenly spaced rows, at most
   ``INIT_SAMPLE_ROWS``) is gathered to the client (:class:`SpreadRows`), the centres are found
   there, and the nearest-centre moments of every partition are merged;
4. every EM iteration sends the parameters to every partition, runs the E-step there
   (:func:`shard_e_step`) and merges the sufficient statistics
   (:class:`~skhmmgmr._hmm._em.Statistics`) in partition order; the M-step runs on the client.

A worker that dies loses its partitions' E-step data: dask recomputes them from the task
graph (reading the partition again), so an iteration survives it.
"""

import os

import numpy as np
import pandas as pd

from .._core._sequences import as_recordings
from .._core._validation import binary_unit, check_finite, constant_to_round_off
from .._hmm._em import e_step
from .._hmm._em_data import Columns, EStepData
from .._hmm._em_init import centre_statistics
from .._hmm._emissions import MomentStatistics
from .._hmm._gaussian import split_moments


class Partition:
    """One partition's rows on a worker: ``values`` (n_rows, n_columns), inputs then target,
    and its recordings."""

    def __init__(self, values, recordings):
        self.values, self.recordings = values, recordings

    def summary(self):
        """``(n_rows, column sums, column maxima of |x|)``."""
        values = self.values
        if not values.shape[0]:
            return 0, np.zeros(values.shape[1]), np.zeros(values.shape[1])
        return values.shape[0], values.sum(axis=0), np.abs(values).max(axis=0)


def load_partition(
    source, features, target, recording="recording", time="time", *, name=None, stamp=None
):
    """Read one partition (a DataFrame or a parquet file path) on a worker.

    ``name`` says which partition it is in errors; ``stamp`` (the file's modification time
    and size, read by the client) is unused here: it is part of the task's key, so that a
    file that changed is read again instead of served from an earlier task.
    """
    where = name or "a partition"
    names = [*features, target]
    if isinstance(source, (str, os.PathLike)):
        source = _read_parquet(source, [recording, *names], time, where)
    missing = [c for c in dict.fromkeys([recording, *names]) if c not in source.columns]
    if missing:
        raise ValueError(
            f"{where} lacks the column(s) {missing}; its columns are {list(source.columns)}"
        )
    if not len(source):  # a filtered dask DataFrame has empty partitions: nothing to fit
        return Partition(np.empty((0, len(names))), None)
    try:
        values = np.ascontiguousarray(source[names].to_numpy(dtype=float))
    except (TypeError, ValueError) as exc:
        bad = next((c for c in names if not pd.api.types.is_numeric_dtype(source[c])), names)
        raise ValueError(
            f"{where}: the column(s) {bad!r} hold values that are not numbers ({exc})"
        ) from None
    stamps = source[time].to_numpy() if time in source.columns else None
    try:
        recordings = as_recordings(
            source[recording].astype(str).to_numpy(), values.shape[0], time=stamps, min_length=2
        )
        check_finite(values, name="data", column_names=names, recordings=recordings)
    except ValueError as exc:
        raise ValueError(f"{where}: {exc}") from None
    return Partition(values, recordings)


def _read_parquet(path, columns, time, where):
    """The columns of a parquet file that it has (plus ``time`` if present), errors named."""
    import pyarrow.parquet as pq

    try:
        present = set(pq.read_schema(path).names)
        wanted = [c for c in dict.fromkeys([*columns, time]) if c in present]
        return pd.read_parquet(path, columns=wanted)
    except (OSError, ValueError) as exc:  # pyarrow's ArrowInvalid is a ValueError
        raise ValueError(f"{where}: the parquet file {str(path)!r} cannot be read: {exc}") from None


def partition_summary(partition):
    """What the client needs from a partition before the fit (no rows)."""
    n_rows, sums, magnitudes = partition.summary()
    return {
        "n_rows": n_rows,
        "sums": sums,
        "magnitudes": magnitudes,
        "ids": np.asarray(partition.recordings.ids if n_rows else []),
        "longest": int(partition.recordings.lengths.max()) if n_rows else 0,
    }


def squared_deviations(partition, center):
    """Per-column sums of squared deviations about ``center``."""
    deviations = partition.values - center
    return np.einsum("ij,ij->j", deviations, deviations)


def standardization(summaries, deviation_sums):
    """``(center, scale)`` of all partitions, as :meth:`Columns.standardized` computes them."""
    n_rows = sum(s["n_rows"] for s in summaries)
    center = sum(s["sums"] for s in summaries) / n_rows
    magnitude = np.max([s["magnitudes"] for s in summaries], axis=0)
    spread = np.sqrt(sum(deviation_sums) / n_rows)
    power = binary_unit(magnitude)
    constant = constant_to_round_off(spread / power, magnitude / power)
    return center, np.where(constant, 1.0, spread)


def make_shard(partition, center, scale, n_states):
    """The E-step data of a partition in the fit's standardised units (about a zero shift)."""
    n_rows, n_columns = partition.values.shape
    values = np.empty((n_columns + 1, n_rows))
    values[:n_columns] = ((partition.values - center) / scale).T
    values[n_columns] = 1.0
    return EStepData(Columns(values, np.zeros(n_columns)), partition.recordings, n_states)


def shard_rows(shard, start, step):
    """Rows ``start::step`` of a shard (about its shift)."""
    return shard.data.rows(slice(start, None, step))


def shard_totals(shard):
    """Moment statistics of all rows of a shard (the pooled moments of the initialisation)."""
    return MomentStatistics(*split_moments(shard.totals[np.newaxis]), shard.shift)


def shard_centre_statistics(shard, centers):
    """Nearest-centre moment statistics of a shard's rows."""
    return centre_statistics(shard, centers)


def shard_e_step(shard, params):
    """The E-step of one partition: its sufficient statistics."""
    return e_step(shard, params)


class SpreadRows:
    """The rows of all partitions, in partition order, as far as the initialisation reads
    them (``n_samples`` and ``rows(index)`` for ``slice(None)`` or ``slice(start, None,
    step)``): the rows asked for are gathered from the workers."""

    def __init__(self, client, shards, counts):
        self.client, self.shards = client, shards
        self.offsets = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(int)
        self.n_samples = int(np.sum(counts))

    def rows(self, index=slice(None)):
        start, step = index.start or 0, index.step or 1
        futures = []
        for shard, offset in zip(self.shards, self.offsets, strict=True):
            first = start - offset if start >= offset else (start - offset) % step
            futures.append(self.client.submit(shard_rows, shard, int(first), step, pure=False))
        return np.concatenate(self.client.gather(futures), axis=0)
