"""Running on a dask cluster: ``use_cluster`` for any search, ``fit_on_cluster`` for one EM."""

from ._dask import WORKER_ENVIRONMENT, fit_on_cluster, use_cluster

__all__ = ["WORKER_ENVIRONMENT", "fit_on_cluster", "use_cluster"]
