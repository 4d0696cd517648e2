"""
Grid search on a dask cluster
=============================

The fits of a ``GridSearchCV`` (and of :func:`~skhmmgmr.selection.select_parameters`, whose
``n_jobs`` goes through joblib too) run on a dask cluster through
``joblib.parallel_backend("dask")``. A local cluster of two threads stands in for a real one;
point a :class:`distributed.Client` at the scheduler of a real cluster instead. The example
prints a message and stops when ``dask.distributed`` is not installed.
"""

import os
import time

import joblib
import matplotlib.pyplot as plt
import sklearn
from sklearn.model_selection import GridSearchCV, GroupKFold

from skhmmgmr import HMMGMRRegressor
from skhmmgmr.datasets import make_driving_protocol
from skhmmgmr.metrics import make_performance_scorers

try:
    from distributed import Client, LocalCluster
except ImportError:
    Client = None
    print("dask.distributed is not installed: pip install 'dask[distributed]'; skipping.")

quick = bool(os.environ.get("SKHMMGMR_DOCS_QUICK"))

# %%
# The search on the cluster
# -------------------------
if Client is not None:
    data = make_driving_protocol(
        drivers=("aggressive",),
        n_validation=0,
        n_test=0,
        duration=8.0 if quick else 40.0,
        sampling_rate=20.0,
        random_state=0,
    )
    features = ["steering_wheel_angle", "yaw_rate"]
    X, y, groups = data[features], data["driver_torque"], data["recording"].to_numpy()
    n_states = [1, 2, 3] if quick else [1, 2, 3, 4, 5, 6]
    with (
        LocalCluster(n_workers=2, processes=False, dashboard_address=None) as cluster,
        Client(cluster) as client,
        sklearn.config_context(enable_metadata_routing=True),
        joblib.parallel_backend("dask"),
    ):
        started = time.perf_counter()
        search = GridSearchCV(
            HMMGMRRegressor(random_state=0),
            {"n_states": n_states},
            cv=GroupKFold(n_splits=3),
            scoring=make_performance_scorers(["50/50"], sampling_period=0.05),
            refit="neg_performance_50/50",
            n_jobs=-1,
        ).fit(X, y, groups=groups)
        elapsed = time.perf_counter() - started
        print(f"{len(n_states) * 3} fits on {len(client.scheduler_info()['workers'])} workers")
    print(f"search took {elapsed:.1f} s; best K at 50/50: {search.best_params_['n_states']}")

    fig, ax = plt.subplots(figsize=(5, 3))
    ax.plot(n_states, -search.cv_results_["mean_test_neg_performance_50/50"], marker="o")
    ax.set(xlabel="number of states K", ylabel="performance score (50/50)")
    ax.set_title("GridSearchCV on a dask LocalCluster")
    fig.tight_layout()
    plt.show()
