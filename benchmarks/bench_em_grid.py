"""Cost of one EM iteration over the shapes the framework uses: engine, fused reference, hmmlearn.

For every number of columns D, number of states K and recording length, the same data
(``_data.make_recordings``, standardised) and the same k-means start are given to

- the package's engine (:func:`skhmmgmr._hmm._em.baum_welch`),
- the fused numba reference (``_fused.py``: one pass per recording, recordings in parallel),
- hmmlearn's ``GaussianHMM(covariance_type="full")`` (``--hmmlearn``; slow),

and the time per iteration is printed side by side with rows per second. Engine and reference
run in turn ``--repeats`` times at every point (interleaved, so that a change of the machine's
load hits both); a time is the smallest interval between two successive log-likelihoods over
the repeats. Both run their compiled parts on ``--threads`` threads (default: numba's, all
cores): the reference by ``prange`` (numba's workqueue layer), the engine on its own pool;
BLAS is limited to one thread. A plot of the cost against K (one line per D) and
against D is written to ``docs/_static/em_grid.png``. Run with::

    python benchmarks/bench_em_grid.py            # the whole grid, about 12 minutes (idle)
    python benchmarks/bench_em_grid.py --quick    # D in {3, 7, 19}, K in {2, 5, 6, 8, 10, 16}
    python benchmarks/bench_em_grid.py --hmmlearn --dims 3 7 --states 5 10   # with hmmlearn
"""

import argparse
import json
import time
from pathlib import Path

import numpy as np
from _data import make_recordings, standardized_joint
from _fused import fused_baum_welch
from bench_em import time_hmmlearn
from numba import config as numba_config
from numba import get_num_threads, set_num_threads
from threadpoolctl import threadpool_limits

from skhmmgmr._core._sequences import Recordings
from skhmmgmr._hmm._em import baum_welch, initialize_parameters

DIMS = (3, 5, 7, 12, 19)
STATES = (2, 3, 4, 5, 6, 7, 8, 9, 10, 12, 16, 20)
LENGTHS = {"30 s": 600, "5 min": 6000}  # rows at 20 Hz
QUICK = {"dims": (3, 7, 19), "states": (2, 5, 6, 8, 10, 16), "lengths": ("5 min",)}
PLOT = Path(__file__).resolve().parents[1] / "docs" / "_static" / "em_grid.png"


def _per_iteration(run):
    stamps = []
    run(lambda *_: stamps.append(time.perf_counter()))
    return float(np.min(np.diff(stamps)))


def measure(n_dims, n_states, length, args):
    n_recordings = max(args.rows // length, 1)
    n_rows = n_recordings * length
    X, y, bounds = make_recordings(n_rows, n_recordings, n_dims - 1, seed=args.seed)
    joint = standardized_joint(X, y)
    recordings = Recordings(ids=np.arange(n_recordings), starts=bounds[:-1], stops=bounds[1:])
    start = initialize_parameters(
        joint, recordings, n_states, "k-means++", 1e-6, np.random.RandomState(args.seed)
    )
    n_iter = args.iterations
    row = {"D": n_dims, "K": n_states, "length": length, "rows": n_rows}
    engine, reference = [], []
    with threadpool_limits(limits=1, user_api="blas"):
        for _ in range(args.repeats):
            engine.append(
                _per_iteration(
                    lambda cb: baum_welch(
                        joint,
                        recordings,
                        start,
                        n_iter=n_iter,
                        tol=0.0,
                        reg_covar=1e-6,
                        callback=cb,
                    )
                )
            )
            reference.append(
                _per_iteration(
                    lambda cb: fused_baum_welch(
                        joint, bounds, start, n_iter=n_iter, reg_covar=1e-6, callback=cb
                    )
                )
            )
        row["engine_s"], row["reference_s"] = min(engine), min(reference)
        if args.hmmlearn:
            times, _ = time_hmmlearn(joint, list(np.diff(bounds)), start, n_iter, "log")
            row["hmmlearn_s"] = float(np.min(times))
    return row


def plot(rows, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    length = max(row["length"] for row in rows)
    rows = [row for row in rows if row["length"] == length]
    fig, (by_k, by_d) = plt.subplots(1, 2, figsize=(11, 4))
    for n_dims in sorted({row["D"] for row in rows}):
        part = sorted((row for row in rows if row["D"] == n_dims), key=lambda row: row["K"])
        ks = [row["K"] for row in part]
        (line,) = by_k.plot(ks, [1e3 * row["engine_s"] for row in part], "o-", label=f"D={n_dims}")
        by_k.plot(ks, [1e3 * row["reference_s"] for row in part], "--", color=line.get_color())
    for n_states in sorted({row["K"] for row in rows} & {2, 5, 10, 16}):
        part = sorted((row for row in rows if row["K"] == n_states), key=lambda row: row["D"])
        ds = [row["D"] for row in part]
        (line,) = by_d.plot(
            ds, [1e3 * row["engine_s"] for row in part], "o-", label=f"K={n_states}"
        )
        by_d.plot(ds, [1e3 * row["reference_s"] for row in part], "--", color=line.get_color())
    by_k.set(
        xlabel="states K", ylabel="ms per EM iteration", title="engine (solid), reference (dashed)"
    )
    by_d.set(xlabel="columns D", ylabel="ms per EM iteration", title=f"recordings of {length} rows")
    by_k.legend(fontsize=8)
    by_d.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rows", type=int, default=540_000)
    parser.add_argument("--iterations", type=int, default=4)
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--threads", type=int, default=None, help="numba threads")
    parser.add_argument("--threading-layer", default="workqueue", help="numba's, for prange")
    parser.add_argument("--hmmlearn", action="store_true", help="also time hmmlearn (slow)")
    parser.add_argument("--quick", action="store_true", help="a subset of the grid")
    parser.add_argument("--dims", type=int, nargs="+", help="values of D (default: the grid)")
    parser.add_argument("--states", type=int, nargs="+", help="values of K (default: the grid)")
    parser.add_argument("--lengths", nargs="+", choices=list(LENGTHS), help="recording lengths")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--output", help="write the rows as JSON")
    parser.add_argument("--plot", default=str(PLOT))
    args = parser.parse_args(argv)
    dims, states, lengths = DIMS, STATES, tuple(LENGTHS)
    if args.quick:
        dims, states, lengths = QUICK["dims"], QUICK["states"], QUICK["lengths"]
    dims, states, lengths = args.dims or dims, args.states or states, args.lengths or lengths
    # The reference's prange on numba's workqueue: OpenMP's spinning workers made it up to 4x
    # slower on a loaded machine (the engine runs its own threads, see _fused_estep).
    numba_config.THREADING_LAYER = args.threading_layer
    if args.threads:
        set_num_threads(args.threads)
    print(f"{args.rows} rows, {get_num_threads()} numba thread(s), {args.repeats} repeats")
    print(
        f"{'length':>6} {'D':>3} {'K':>3} {'engine ms':>10} {'ref ms':>8} {'ratio':>6} "
        f"{'hmmlearn ms':>11} {'engine Mrows/s':>14}"
    )
    rows = []
    for name in lengths:
        for n_dims in dims:
            for n_states in states:
                row = measure(n_dims, n_states, LENGTHS[name], args)
                rows.append(row)
                peer = f"{1e3 * row['hmmlearn_s']:>11.0f}" if "hmmlearn_s" in row else f"{'-':>11}"
                print(
                    f"{name:>6} {n_dims:>3} {n_states:>3} {1e3 * row['engine_s']:>10.1f} "
                    f"{1e3 * row['reference_s']:>8.1f} "
                    f"{row['engine_s'] / row['reference_s']:>6.2f} {peer} "
                    f"{row['rows'] / row['engine_s'] / 1e6:>14.1f}",
                    flush=True,
                )
                if args.output:  # after every point: a cut run keeps what it measured
                    Path(args.output).write_text(json.dumps(rows, indent=1))
    plot(rows, args.plot)
    print(f"plot: {args.plot}")
    return rows


if __name__ == "__main__":
    main()
