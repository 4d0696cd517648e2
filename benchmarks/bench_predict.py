"""Prediction throughput: ``HMMGMRRegressor.predict`` against ``gmr``'s GMR.

A K=5 model over 3 inputs is fitted on generated recordings; then ``predict`` (causal forward
filter on the inputs + GMR, restarting at every recording) and
``gmr.sklearn.GaussianMixtureRegressor.predict`` (plain GMR with the same joint Gaussians and
no forward recursion) are timed on the same rows, on one BLAS thread. The table shows median
seconds over repeats, rows per second and the ratio. Needs ``pip install gmr`` (the ``bench``
extra). Run with::

    python benchmarks/bench_predict.py
"""

import argparse
import time

import numpy as np
from _data import make_recordings
from gmr import GMM
from gmr.sklearn import GaussianMixtureRegressor
from threadpoolctl import threadpool_limits

from skhmmgmr import HMMGMRRegressor


def median_time(function, repeats):
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        function()
        times.append(time.perf_counter() - start)
    return float(np.median(times))


def run_case(n_rows, n_recordings, model, n_inputs, repeats):
    X, _, bounds = make_recordings(n_rows, n_recordings, n_inputs, seed=1)
    groups = np.repeat(np.arange(n_recordings), np.diff(bounds))
    peer = GaussianMixtureRegressor(n_components=model.n_states)
    peer.gmm_ = GMM(
        n_components=model.n_states,
        priors=model.startprob_,
        means=model.means_,
        covariances=model.covars_,
    )
    peer.indices_ = np.arange(n_inputs)
    ours_pred = model.predict(X, groups=groups)
    peer_pred = peer.predict(X)
    assert ours_pred.shape == peer_pred[:, 0].shape
    ours = median_time(lambda: model.predict(X, groups=groups), repeats)
    theirs = median_time(lambda: peer.predict(X), repeats)
    name = f"{n_rows} rows / {n_recordings} rec"
    print(
        f"{name:<22} {ours:>9.4f} {theirs:>9.4f} {theirs / ours:>7.2f}x "
        f"{n_rows / ours / 1e6:>12.2f} {n_rows / theirs / 1e6:>12.2f}"
    )
    return {
        "case": name,
        "ours_s": ours,
        "gmr_s": theirs,
        "ratio": theirs / ours,
        "ours_rows_per_s": n_rows / ours,
        "gmr_rows_per_s": n_rows / theirs,
    }


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n-states", type=int, default=5)
    parser.add_argument("--n-inputs", type=int, default=3)
    parser.add_argument("--repeats", type=int, default=15)
    parser.add_argument("--threads", type=int, default=1, help="BLAS/OpenMP threads")
    args = parser.parse_args(argv)
    X, y, bounds = make_recordings(50_000, 10, args.n_inputs, seed=0)
    groups = np.repeat(np.arange(10), np.diff(bounds))
    print(
        f"K={args.n_states}, {args.n_inputs} inputs, {args.threads} thread(s), medians of "
        f"{args.repeats} repeats"
    )
    print(
        f"{'case':<22} {'ours (s)':>9} {'gmr (s)':>9} {'ratio':>8} "
        f"{'ours Mrow/s':>12} {'gmr Mrow/s':>12}"
    )
    with threadpool_limits(limits=args.threads):
        model = HMMGMRRegressor(n_states=args.n_states, random_state=0).fit(X, y, groups=groups)
        return [
            run_case(n_rows, n_recordings, model, args.n_inputs, args.repeats)
            for n_rows, n_recordings in [(100_000, 20), (500_000, 84)]
        ]


if __name__ == "__main__":
    main()
