"""Latency of one streaming update against ``predict`` on a one-row array.

Fits a K=5, 3-input HMM-GMR model on generated recordings, then times 20,000 single calls of
``FilterStream.update``, 20,000 of an adapting stream's update with the measured target
(``relevance=16``: online MAP adaptation of the state means, with and without forgetting)
and 2,000 of ``model.predict`` with ``time.perf_counter_ns``, and prints the median and 99th
percentile in microseconds, and the cost of an adapting update relative to a plain one
(target: at most 3x). Then the stream of a whole ``make_torque_pipeline`` (K=5, the three
sensed inputs it derives from, velocity filter on: 8 inputs reach the regressor) on the sensed
rows, against the stream of its regressor alone on the derived rows (target: at most 1.5x).
Run with::

    python benchmarks/bench_streaming.py
"""

import time

import numpy as np
import pandas as pd

from skhmmgmr import HMMGMRRegressor, make_torque_pipeline

N_STATES = 5
N_UPDATES = 20_000
N_PREDICTS = 2_000


def make_data(n_recordings=4, length=500, seed=0):
    """Random-walk inputs and a torque that is a nonlinear function of them."""
    rng = np.random.default_rng(seed)
    X = np.cumsum(rng.normal(scale=0.2, size=(n_recordings * length, 3)), axis=0)
    y = 2.0 * np.tanh(X[:, 0]) - 0.5 * X[:, 1] + 0.3 * np.sin(X[:, 2])
    y += rng.normal(scale=0.05, size=len(y))
    groups = np.repeat(np.arange(n_recordings), length)
    return X, y, groups


def time_calls(function, rows, n_calls, targets=None):
    clock = time.perf_counter_ns
    elapsed = np.empty(n_calls, dtype=np.int64)
    for i in range(n_calls):
        row = rows[i % len(rows)]
        if targets is None:
            start = clock()
            function(row)
        else:
            target = float(targets[i % len(rows)])
            start = clock()
            function(row, target=target)
        elapsed[i] = clock() - start
    return elapsed / 1000.0


def report(name, microseconds):
    median, p99 = np.median(microseconds), np.percentile(microseconds, 99)
    print(f"{name:<34} median {median:8.2f} us   p99 {p99:8.2f} us   ({len(microseconds)} calls)")


def main():
    X, y, groups = make_data()
    model = HMMGMRRegressor(n_states=N_STATES, random_state=0).fit(X, y, groups=groups)
    rows, targets = X[groups == 0], y[groups == 0]
    streams = {
        "FilterStream.update (1 sample)": (model.filter_stream(), None),
        "  adapting, forgetting=1": (model.filter_stream(relevance=16.0), targets),
        "  adapting, forgetting=0.999": (
            model.filter_stream(relevance=16.0, forgetting=0.999),
            targets,
        ),
    }
    # Warm up caches and BLAS, then time the streams in turn, in 4 rounds, so that a load
    # change on a shared machine affects them alike.
    for stream, with_targets in streams.values():
        time_calls(stream.update, rows, 1000, with_targets)
    elapsed = {name: [] for name in streams}
    for _ in range(4):
        for name, (stream, with_targets) in streams.items():
            elapsed[name].append(time_calls(stream.update, rows, N_UPDATES // 4, with_targets))
    plain = np.concatenate(elapsed["FilterStream.update (1 sample)"])
    for name, parts in elapsed.items():
        report(name, np.concatenate(parts))
        if name.startswith("  "):
            ratio = np.median(np.concatenate(parts)) / np.median(plain)
            print(f"{'':<34} {ratio:.2f}x a plain update (median; target <= 3x)")
    one_row = rows[:, np.newaxis, :]
    report("model.predict (1-row array)", time_calls(model.predict, one_row, N_PREDICTS))
    pipeline_streams()


def pipeline_streams():
    """The stream of a torque pipeline on sensed rows against its regressor's stream on the
    derived rows (the same filter, the derived inputs computed outside the timing)."""
    X, y, groups = make_data()
    names = ["steering_wheel_angle", "steering_wheel_velocity", "lateral_acceleration"]
    X = pd.DataFrame(X, columns=names)
    pipeline = make_torque_pipeline(
        N_STATES, velocity_filter=0.02, sampling_period=0.01, random_state=0
    ).fit(X, y, groups=groups)
    sensed = X[groups == 0].to_numpy()
    derived = pipeline[:-1].transform(X[groups == 0]).to_numpy()
    streams = {
        "regressor stream (derived rows)": (pipeline[-1].filter_stream(), derived),
        "pipeline stream (sensed rows)": (pipeline.filter_stream(), sensed),
    }
    for stream, rows in streams.values():
        time_calls(stream.update, rows, 1000)
    elapsed = {name: [] for name in streams}
    for _ in range(4):
        for name, (stream, rows) in streams.items():
            stream.reset()
            elapsed[name].append(time_calls(stream.update, rows, N_UPDATES // 4))
    print(f"\ntorque pipeline, K={N_STATES}, {derived.shape[1]} inputs to the regressor:")
    bare = np.concatenate(elapsed["regressor stream (derived rows)"])
    for name, parts in elapsed.items():
        report(name, np.concatenate(parts))
    ratio = np.median(np.concatenate(elapsed["pipeline stream (sensed rows)"])) / np.median(bare)
    print(f"{'':<34} {ratio:.2f}x the regressor's update (median; target <= 1.5x)")


if __name__ == "__main__":
    main()
