"""Time per Baum-Welch iteration: skhmmgmr's EM engine against hmmlearn's GaussianHMM.

Both start from the same parameters on the same standardised data, without regularisation
(``reg_covar=0`` here, ``covars_prior=0, covars_weight=0`` for hmmlearn), and run
``--iterations`` iterations. The time of an iteration is the interval between two successive
log-likelihood reports (one M-step plus one E-step in both libraries); the table shows medians
and the largest relative difference between the two log-likelihood histories. Run with::

    python benchmarks/bench_em.py                 # thesis scale, about 2 minutes
    python benchmarks/bench_em.py --rows 50000    # quick check
"""

import argparse
import time
import warnings

import numpy as np
from _data import make_recordings, standardized_joint
from hmmlearn.hmm import GaussianHMM
from threadpoolctl import threadpool_limits

from skhmmgmr._core._sequences import Recordings
from skhmmgmr._hmm._em import baum_welch, initialize_parameters

CASES = {"3 dims, K=5": (2, 5), "9 dims, K=5": (8, 5), "19 dims, K=2": (18, 2)}


def time_ours(joint, recordings, start, n_iter):
    stamps = []
    result = baum_welch(
        joint,
        recordings,
        start,
        n_iter=n_iter,
        tol=0.0,
        reg_covar=0.0,
        callback=lambda *_: stamps.append(time.perf_counter()),
    )
    return np.diff(stamps), np.asarray(result.history[:n_iter])


def time_hmmlearn(joint, lengths, start, n_iter, implementation):
    n_states, n_dims = start.means.shape
    peer = GaussianHMM(
        n_components=n_states,
        covariance_type="full",
        n_iter=n_iter,
        tol=-np.inf,
        init_params="",
        covars_prior=np.zeros((n_states, n_dims, n_dims)),
        covars_weight=0,
        implementation=implementation,
    )
    peer.startprob_ = start.startprob.copy()
    peer.transmat_ = start.transmat.copy()
    peer.means_ = start.means.copy()
    peer.covars_ = start.covariances.copy()
    stamps = []
    report = peer.monitor_.report

    def timed_report(log_prob):
        stamps.append(time.perf_counter())
        report(log_prob)

    peer.monitor_.report = timed_report
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        peer.fit(joint, lengths=lengths)
    return np.diff(stamps), np.asarray(peer.monitor_.history)


def run_case(name, n_inputs, n_states, args):
    X, y, bounds = make_recordings(args.rows, args.recordings, n_inputs, seed=args.seed)
    joint = standardized_joint(X, y)
    recordings = Recordings(ids=np.arange(args.recordings), starts=bounds[:-1], stops=bounds[1:])
    start = initialize_parameters(
        joint, recordings, n_states, "k-means++", 1e-6, np.random.RandomState(args.seed)
    )
    ours_times, peer_times = [], []
    for _ in range(args.repeats):
        times, ours_history = time_ours(joint, recordings, start, args.iterations)
        ours_times.extend(times)
        times, peer_history = time_hmmlearn(
            joint, list(np.diff(bounds)), start, args.iterations, args.implementation
        )
        peer_times.extend(times)
    rel_diff = np.max(np.abs(ours_history - peer_history) / np.abs(peer_history))
    ours, peer = np.median(ours_times), np.median(peer_times)
    print(f"{name:<14} {ours:>10.4f} {peer:>10.4f} {peer / ours:>7.1f}x {rel_diff:>12.1e}")
    return {
        "case": name,
        "ours_s": ours,
        "hmmlearn_s": peer,
        "ratio": peer / ours,
        "max_rel_ll_diff": rel_diff,
    }


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rows", type=int, default=500_000)
    parser.add_argument("--recordings", type=int, default=84)
    parser.add_argument("--iterations", type=int, default=6)
    parser.add_argument("--repeats", type=int, default=1)
    parser.add_argument("--threads", type=int, default=1, help="BLAS/OpenMP threads")
    parser.add_argument("--implementation", default="log", choices=["log", "scaling"])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--case", action="append", choices=list(CASES), default=None)
    args = parser.parse_args(argv)
    print(
        f"{args.rows} rows in {args.recordings} recordings, {args.iterations} iterations x "
        f"{args.repeats} repeat(s), {args.threads} thread(s), hmmlearn "
        f"implementation={args.implementation!r}"
    )
    print(f"{'case':<14} {'ours (s)':>10} {'peer (s)':>10} {'ratio':>8} {'max rel LL':>12}")
    with threadpool_limits(limits=args.threads):
        return [run_case(name, *CASES[name], args) for name in args.case or CASES]


if __name__ == "__main__":
    main()
