"""The package on a real dask cluster: worker processes, a killed worker, a killed driver, and
one EM fit over partitions held by the workers.

Every result is compared with the same computation on one machine.
"""

import os
import signal
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from _protocol_data import PERIOD, make_protocol
from sklearn.model_selection import PredefinedSplit

from skhmmgmr import HMMGMRRegressor
from skhmmgmr.cluster import WORKER_ENVIRONMENT, _scatter, fit_on_cluster, use_cluster
from skhmmgmr.feature_selection import ExhaustiveFeatureSelector
from skhmmgmr.selection import select_parameters
from skhmmgmr.selection._search import _evaluation

distributed = pytest.importorskip(
    "distributed", reason="dask.distributed is not installed (pip install 'dask[distributed]')"
)

TABLES = [
    "filter",
    "relevance",
    "candidates",
    "candidate_scores",
    "states",
    "state_choices",
    "bic",
    "anova",
    "test",
    "exhaustive",
    "forward_paths",
]
FEATURES = [f"f{i}" for i in range(5)]


@pytest.fixture(scope="module")
def cluster():
    with distributed.LocalCluster(
        n_workers=2,
        processes=True,
        threads_per_worker=1,
        dashboard_address=None,
        env=WORKER_ENVIRONMENT,
    ) as cluster:
        yield cluster
    _scatter.release_scattered()


@pytest.fixture(scope="module")
def search_data():
    """Enough fits (31 subsets) of sizeable recordings for a kill to land mid-search."""
    data = make_protocol(n_recordings=(4, 3, 0), length=1000, n_features=5)
    cv = PredefinedSplit(np.where(data["split"] == "validation", 0, -1))
    return data[FEATURES], data["driver_torque"], data["recording"], cv


def _cached(folder):
    """Output file -> modification time of every finished evaluation in a joblib cache."""
    return {path: path.stat().st_mtime_ns for path in Path(folder).rglob("output.pkl")}


def _worker_pids(client):
    return client.run(os.getpid)


def test_select_parameters_on_worker_processes_equals_the_local_run(cluster):
    data = make_protocol()
    local = select_parameters(data, k_max=3, progress=False)
    with distributed.Client(cluster) as client:
        scatters, scatter = [], client.scatter

        def counting_scatter(*args, **kwargs):
            scatters.append(args)
            return scatter(*args, **kwargs)

        client.scatter = counting_scatter
        with use_cluster(client):
            remote = select_parameters(data, k_max=3, progress=False)
        # the work ran in the worker processes, not in this one
        assert os.getpid() not in _worker_pids(client).values()
    for name in TABLES:
        pd.testing.assert_frame_equal(getattr(remote, name), getattr(local, name), obj=name)
    assert (remote.features, remote.n_states) == (local.features, local.n_states)
    # the recordings went out once per data table of the framework, not once per task
    n_tasks = len(local.exhaustive) + len(local.forward_paths) + len(local.states)
    assert 1 <= len(scatters) <= 4 < n_tasks


def _kill_a_worker_when(client, ready, killed):
    """Kill one worker process (SIGKILL) as soon as ``ready()``; record what it saw."""
    pid = next(iter(_worker_pids(client).values()))
    deadline = time.monotonic() + 60
    while not ready() and time.monotonic() < deadline:
        time.sleep(0.01)
    killed["before"] = ready()
    os.kill(pid, signal.SIGKILL)
    killed["pid"] = pid


def test_a_worker_killed_mid_search_changes_nothing_and_loses_no_finished_work(
    cluster, search_data, tmp_path
):
    X, y, groups, cv = search_data
    local = ExhaustiveFeatureSelector(cv=cv, sampling_period=PERIOD).fit(X, y, groups=groups)
    n_tasks = len(local.results_) // 3  # three validation recordings per subset
    killed, finished = {}, {}

    def two_finished():
        found = _cached(tmp_path)
        if len(found) >= 2:
            finished.update(found)
            return True
        return False

    with distributed.Client(cluster) as client, use_cluster(client):
        killer = threading.Thread(target=_kill_a_worker_when, args=(client, two_finished, killed))
        killer.start()
        remote = ExhaustiveFeatureSelector(cv=cv, sampling_period=PERIOD, memory=str(tmp_path))
        remote.fit(X, y, groups=groups)
        killer.join()
        client.wait_for_workers(2, timeout=60)
        assert killed["pid"] not in _worker_pids(client).values()
    assert killed["before"] and len(finished) < n_tasks  # killed mid-search
    pd.testing.assert_frame_equal(remote.results_, local.results_)
    after = _cached(tmp_path)
    assert len(after) == n_tasks
    # the evaluations finished before the kill were kept, not computed again
    assert {path: after[path] for path in finished} == finished


DRIVER = """
import sys
sys.path.insert(0, {tests!r})
import numpy as np
from _protocol_data import make_protocol
from sklearn.model_selection import PredefinedSplit
from skhmmgmr.cluster import use_cluster
from skhmmgmr.feature_selection import ExhaustiveFeatureSelector

data = make_protocol(n_recordings=(4, 3, 0), length=1000, n_features=5)
cv = PredefinedSplit(np.where(data["split"] == "validation", 0, -1))
with use_cluster({address!r}):
    ExhaustiveFeatureSelector(cv=cv, sampling_period={period!r}, memory={memory!r}).fit(
        data[{features!r}], data["driver_torque"], groups=data["recording"]
    )
"""


def test_a_killed_driver_resumes_from_memory(cluster, search_data, tmp_path):
    X, y, groups, cv = search_data
    memory = tmp_path / "cache"
    script = tmp_path / "driver.py"
    script.write_text(
        textwrap.dedent(
            DRIVER.format(
                tests=str(Path(__file__).parent),
                address=cluster.scheduler_address,
                period=PERIOD,
                memory=str(memory),
                features=FEATURES,
            )
        )
    )
    driver = subprocess.Popen([sys.executable, str(script)])
    try:
        deadline = time.monotonic() + 120
        while len(_cached(memory)) < 3 and driver.poll() is None:
            assert time.monotonic() < deadline, "the driver finished no evaluation in time"
            time.sleep(0.01)
        driver.send_signal(signal.SIGKILL)
    finally:
        driver.kill()
        driver.wait()
    assert driver.returncode == -signal.SIGKILL  # killed, not finished
    time.sleep(1.0)  # evaluations still running on the workers end and are cached
    before = _cached(memory)
    local = ExhaustiveFeatureSelector(cv=cv, sampling_period=PERIOD).fit(X, y, groups=groups)
    n_tasks = len(local.results_) // 3
    assert 3 <= len(before) < n_tasks
    # The package's source is part of the cache key, read once per process: read it again
    # as the driver did (it only changes here when the checkout is edited during the test).
    _evaluation._installed_code.cache_clear()
    with use_cluster(cluster.scheduler_address):
        resumed = ExhaustiveFeatureSelector(cv=cv, sampling_period=PERIOD, memory=str(memory))
        resumed.fit(X, y, groups=groups)
    pd.testing.assert_frame_equal(resumed.results_, local.results_)
    after = _cached(memory)
    assert len(after) == n_tasks
    assert {path: after[path] for path in before} == before  # not computed again


@pytest.fixture(scope="module")
def fit_data():
    return make_protocol(n_recordings=(6, 0, 0), length=400)


def _assert_same_fit(remote, local):
    for name in ["startprob_", "transmat_", "means_", "covars_"]:
        np.testing.assert_allclose(
            getattr(remote, name), getattr(local, name), rtol=1e-10, atol=1e-10
        )
    assert remote.n_iter_ == local.n_iter_ and remote.converged_ == local.converged_
    np.testing.assert_allclose(
        remote.log_likelihood_history_, local.log_likelihood_history_, rtol=1e-10
    )


@pytest.mark.parametrize("layout", ["frames", "parquet", "dask"])
def test_fit_on_cluster_equals_the_single_machine_fit(cluster, fit_data, tmp_path, layout):
    features = ["f0", "f1", "f2"]
    params = dict(n_states=3, random_state=0, tol=1e-8, n_iter=200)
    local = HMMGMRRegressor(**params).fit(
        fit_data[features], fit_data["driver_torque"], groups=fit_data["recording"]
    )
    by_partition = [["train0", "train1"], ["train2"], ["train3", "train4", "train5"]]
    parts = [fit_data[fit_data["recording"].isin(ids)] for ids in by_partition]
    if layout == "parquet":
        paths = [tmp_path / f"part-{i}.parquet" for i in range(len(parts))]
        for part, path in zip(parts, paths, strict=True):
            part.to_parquet(path)
        parts = [str(path) for path in paths]
    elif layout == "dask":
        dd = pytest.importorskip("dask.dataframe")
        parts = dd.concat([dd.from_pandas(part, npartitions=1) for part in parts])
    with distributed.Client(cluster) as client:
        if layout == "frames":  # the client of the enclosing block
            with use_cluster(client):
                remote = fit_on_cluster(HMMGMRRegressor(**params), parts, features=features)
        else:
            remote = fit_on_cluster(
                HMMGMRRegressor(**params), parts, features=features, client=client
            )
    _assert_same_fit(remote, local)
    frame = fit_data[features]
    np.testing.assert_allclose(
        remote.predict(frame, groups=fit_data["recording"]),
        local.predict(frame, groups=fit_data["recording"]),
        rtol=1e-9,
        atol=1e-12,
    )


def test_fit_on_cluster_refuses_a_recording_split_over_partitions(cluster, fit_data):
    half = len(fit_data) // 2 + 7
    parts = [fit_data.iloc[:half], fit_data.iloc[half:]]
    with (
        distributed.Client(cluster) as client,
        pytest.raises(ValueError, match="lies in partitions 0 and 1"),
    ):
        fit_on_cluster(HMMGMRRegressor(n_states=2), parts, features=["f0"], client=client)
    with pytest.raises(ValueError, match="init_params='random'"):
        fit_on_cluster(HMMGMRRegressor(init_params="random"), parts, features=["f0"], client=client)
    for smoothing in ("auto", -1.0, np.inf):
        with pytest.raises(ValueError, match="output_smoothing"):
            model = HMMGMRRegressor(output_smoothing=smoothing)
            fit_on_cluster(model, parts, features=["f0"], client=client)


def test_fit_on_cluster_keeps_the_read_out(cluster, fit_data):
    features, params = ["f0", "f1"], dict(n_states=2, random_state=0, output_smoothing=3.0)
    local = HMMGMRRegressor(**params).fit(
        fit_data[features], fit_data["driver_torque"], groups=fit_data["recording"]
    )
    parts = [fit_data[fit_data["recording"].isin(["train0", "train1"])]]
    parts.append(fit_data[~fit_data["recording"].isin(["train0", "train1"])])
    with distributed.Client(cluster) as client:
        remote = fit_on_cluster(HMMGMRRegressor(**params), parts, features=features, client=client)
    assert remote.output_smoothing_ == pytest.approx(3.0, rel=1e-12)
    frame, groups = fit_data[features], fit_data["recording"]
    np.testing.assert_allclose(
        remote.predict(frame, groups=groups), local.predict(frame, groups=groups), atol=1e-9
    )


@pytest.mark.parametrize(
    ("params", "named"),
    [
        ({"n_states": 0}, "n_states"),
        ({"tol": -1.0}, "tol"),
        ({"covariance_type": "round"}, "covariance_type"),
    ],
)
def test_fit_on_cluster_checks_the_parameters_as_fit_does(fit_data, params, named):
    # refused before any client is looked for or any partition read, naming the parameter
    from sklearn.utils._param_validation import InvalidParameterError

    with pytest.raises(InvalidParameterError, match=f"'{named}' parameter"):
        fit_on_cluster(HMMGMRRegressor(**params), [fit_data], features=["f0"], client=object())
    with pytest.raises(InvalidParameterError, match=f"'{named}' parameter"):
        HMMGMRRegressor(**params).fit(fit_data[["f0"]], fit_data["driver_torque"])


def test_select_command_on_a_scheduler_writes_the_local_tables(cluster, tmp_path, capsys):
    pytest.importorskip("matplotlib")
    from skhmmgmr.cli import main

    data = make_protocol().rename(columns={"driver_torque": "torque"})
    path = tmp_path / "runs.csv"
    data.to_csv(path, index=False)
    argv = ["select", str(path), "--target", "torque", "--n-top", "3", "--k-max", "2"]
    argv += ["--trade-off-step", "50", "--quiet"]
    assert main([*argv, "--n-jobs", "1", "--output", str(tmp_path / "local")]) == 0
    address = cluster.scheduler_address
    assert main([*argv, "--scheduler", address, "--output", str(tmp_path / "remote")]) == 0
    for table in ("candidates", "states", "test_summary", "per_driver"):
        pd.testing.assert_frame_equal(
            pd.read_csv(tmp_path / "remote" / f"{table}.csv"),
            pd.read_csv(tmp_path / "local" / f"{table}.csv"),
        )
    manifest = (tmp_path / "remote" / "manifest.json").read_text()
    assert address in manifest


# --- #35: changed files are read again; faults name the partition or the file ----------------


def test_a_parquet_file_that_changed_is_read_again(cluster, fit_data, tmp_path):
    """Load tasks were keyed by path: while a task of the old contents was alive (another
    fit, a future still held), a fit after the file changed was served the old rows."""
    from skhmmgmr.cluster._dask import _partitions

    features = ["f0", "f1"]
    params = dict(n_states=2, random_state=0, tol=1e-8, n_iter=50)
    path = tmp_path / "part.parquet"
    old = fit_data[fit_data["recording"].isin(["train0", "train1"])]
    new = fit_data[fit_data["recording"].isin(["train2", "train3", "train4"])]
    with distributed.Client(cluster) as client:
        old.to_parquet(path)
        held = _partitions(client, [str(path)], features, "driver_torque")
        client.gather(held)
        new.to_parquet(path)
        again = _partitions(client, [str(path)], features, "driver_torque")
        assert again[0].key != held[0].key
        assert client.gather(again)[0].values.shape[0] == len(new)
        after = fit_on_cluster(
            HMMGMRRegressor(**params), [str(path)], features=features, client=client
        )
        del held, again
    local = HMMGMRRegressor(**params).fit(
        new[features], new["driver_torque"], groups=new["recording"]
    )
    _assert_same_fit(after, local)


def test_empty_partitions_are_left_out(cluster, fit_data):
    features = ["f0", "f1"]
    params = dict(n_states=2, random_state=0, tol=1e-8, n_iter=50)
    rows = fit_data[fit_data["recording"].isin(["train0", "train1"])]
    with distributed.Client(cluster) as client:
        remote = fit_on_cluster(
            HMMGMRRegressor(**params),
            [rows.iloc[:0], rows, rows.iloc[:0]],
            features=features,
            client=client,
        )
        with pytest.raises(ValueError, match="every one of the 2 partition"):
            fit_on_cluster(
                HMMGMRRegressor(**params), [rows.iloc[:0]] * 2, features=features, client=client
            )
    local = HMMGMRRegressor(**params).fit(
        rows[features], rows["driver_torque"], groups=rows["recording"]
    )
    _assert_same_fit(remote, local)


@pytest.mark.parametrize(
    "fault, message",
    [
        (
            "missing column",
            r"partition 1 \(the file '.*part-1.parquet'\) lacks the column\(s\) \['f1'\]",
        ),
        ("text", r"partition 1 \(the file '.*part-1.parquet'\): the column\(s\) 'f0' hold values"),
        (
            "no recording",
            r"partition 1 \(the file '.*part-1.parquet'\) lacks the column\(s\) \['recording'\]",
        ),
        (
            "not parquet",
            r"partition 1 \(the file '.*part-1.parquet'\): the parquet file .* cannot be read",
        ),
    ],
)
def test_a_faulty_partition_is_named(cluster, fit_data, tmp_path, fault, message):
    rows = fit_data[fit_data["recording"].isin(["train0", "train1"])]
    other = fit_data[fit_data["recording"].isin(["train2"])]
    paths = [tmp_path / "part-0.parquet", tmp_path / "part-1.parquet"]
    rows.to_parquet(paths[0])
    if fault == "missing column":
        other.drop(columns="f1").to_parquet(paths[1])
    elif fault == "text":
        other.assign(f0="abc").to_parquet(paths[1])
    elif fault == "no recording":
        other.drop(columns="recording").to_parquet(paths[1])
    else:
        paths[1].write_text("not parquet")
    with distributed.Client(cluster) as client, pytest.raises(ValueError, match=message):
        fit_on_cluster(
            HMMGMRRegressor(n_states=2),
            [str(p) for p in paths],
            features=["f0", "f1"],
            client=client,
        )
