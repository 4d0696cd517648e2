"""The selection search on a dask cluster: the recordings shipped to the workers once.

Under joblib's dask backend (``joblib.parallel_config(backend="dask")``) the evaluations of a
search (``evaluate_models`` of ``selection/_search/_evaluation.py``) are dask tasks. Their data, the
training and validation arrays of every split (a list of tuples of arrays, which joblib would
pickle into every task), are scattered to every worker once instead (``broadcast=True``: a
worker that dies leaves the other copies, so its tasks are rerun elsewhere), and every task
receives the future. The future is kept for the next search step on the same data (the
framework runs a dozen of them), keyed by the client and a hash of the arrays, so that one
framework run ships the recordings once per worker.
"""

import joblib

# (client id, data hash) -> future of the scattered fold arrays; the latest four are kept
# (the framework's steps see three or four tables).
_SCATTERED = {}
_KEPT = 4


def dask_client():
    """The ``distributed.Client`` of joblib's active dask backend, else None."""
    backend, _ = joblib.parallel.get_active_backend()
    if type(backend).__name__ != "DaskDistributedBackend":
        return None
    return backend.client


def scatter_once(client, folds):
    """A future of ``folds`` held by every worker of ``client``, scattered at most once.

    A future whose data were lost (every worker holding them died) is scattered again.
    """
    key = (client.id, joblib.hash(folds))
    future = _SCATTERED.get(key)
    if future is None or future.status != "finished":
        # In a list: a list itself would be scattered element by element.
        (future,) = client.scatter([folds], broadcast=True, hash=False)
        _SCATTERED.pop(key, None)
        _SCATTERED[key] = future
        while len(_SCATTERED) > _KEPT:
            _SCATTERED.pop(next(iter(_SCATTERED)))
    return future


def release_scattered():
    """Drop the futures kept for later search steps (their data leave the workers)."""
    _SCATTERED.clear()
