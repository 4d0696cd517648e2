"""Every speed and memory figure of the package, against its target, in one command.

Runs, one after the other on this machine:

1. ``bench_em``: time per Baum-Welch iteration against hmmlearn's ``GaussianHMM`` (full
   covariance) at 500,000 rows in 84 recordings, three cases, one thread, with the largest
   relative difference of the log-likelihood histories (target: at least 10x, at most 1e-6);
2. ``bench_predict``: filter + GMR throughput, K=5 and 3 inputs, one thread, against ``gmr``
   (target: at least 2 million rows per second, and faster than gmr);
3. ``bench_framework``: the whole selection framework on 7 simulated drivers at 20 Hz, the
   hmmlearn estimate of its exhaustive step and the slow reference path with a comparison of
   the selections (target: at most 10 minutes on 2 cores, same selections);
4. ``bench_memory``: peak resident memory of fitting 2.5 million rows x 19 columns, K=5
   (target: below 1.5 GB).

Run from the repository root, with the ``bench`` extra installed (``pip install -e
".[bench]"``)::

    python benchmarks/bench_speed.py                        # about 50 minutes on 2 cores
    python benchmarks/bench_speed.py --skip-reference       # about 12 minutes
    python benchmarks/bench_speed.py --output results.json  # also write the figures
    python benchmarks/bench_speed.py --save tables          # keep both paths' selection tables
    python benchmarks/bench_speed.py --reference-tables tables/reference_path.joblib
                                                # compare with a saved reference run, ~12 min

Timings are only meaningful on an otherwise idle machine.
"""

import argparse
import json
import platform
import sys

import bench_em
import bench_framework
import bench_memory
import bench_predict
import numpy as np


def _versions():
    import hmmlearn
    import numba
    import sklearn

    import skhmmgmr

    return {
        "python": platform.python_version(),
        "numpy": np.__version__,
        "scikit-learn": sklearn.__version__,
        "hmmlearn": hmmlearn.__version__,
        "numba": numba.__version__,
        "skhmmgmr": skhmmgmr.__version__,
        "machine": f"{platform.machine()}, {platform.processor() or 'cpu'}",
    }


def _check(label, value, passed):
    print(f"  [{'ok' if passed else 'MISSED'}] {label}: {value}")
    return passed


def summarise(results):
    """Print every figure against its target; returns True when all are met."""
    print("\nTargets")
    ok = True
    for case in results["em"]:
        ok &= _check(
            f"EM {case['case']}",
            f"{case['ratio']:.1f}x faster than hmmlearn per iteration ({case['ours_s'] * 1e3:.0f}"
            f" vs {case['hmmlearn_s'] * 1e3:.0f} ms), log-likelihoods within "
            f"{case['max_rel_ll_diff']:.1e}",
            case["ratio"] >= 10 and case["max_rel_ll_diff"] <= 1e-6,
        )
    for case in results["predict"]:
        ok &= _check(
            f"predict {case['case']}",
            f"{case['ours_rows_per_s'] / 1e6:.1f} M rows/s, {case['ratio']:.1f}x gmr",
            case["ours_rows_per_s"] >= 2e6 and case["ratio"] > 1,
        )
    framework = results.get("framework")
    if framework:
        ok &= _check(
            "framework, 7 drivers",
            f"{framework['framework_wall_s']:.0f} s wall on {results['n_jobs']} cores",
            framework["framework_wall_s"] <= 600,
        )
        if "peer" in framework:
            peer = framework["peer"]
            print(
                f"  [info] exhaustive step: {peer['ours_exhaustive_measured_s']:.0f} s measured; "
                f"hmmlearn extrapolated {peer['peer_exhaustive_s']:.0f} s "
                f"({peer['peer_exhaustive_s'] / peer['ours_exhaustive_measured_s']:.0f}x)"
            )
        if "comparison" in framework:
            comparison = framework["comparison"]
            ok &= _check(
                "same selections as the reference path",
                f"subset {comparison['same_subset']}, K {comparison['same_n_states']}, "
                f"reference path {framework['reference_wall_s']:.0f} s",
                comparison["same_subset"] and comparison["same_n_states"],
            )
    memory = results.get("memory")
    if memory:
        ok &= _check(
            "memory",
            f"peak {memory['peak_mb']:.0f} MB resident ({memory['data_mb']:.0f} MB of data)",
            memory["peak_mb"] < 1536,
        )
    return ok


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n-jobs", type=int, default=2, help="workers of the framework")
    parser.add_argument("--skip-reference", action="store_true")
    parser.add_argument("--skip-framework", action="store_true")
    parser.add_argument("--cache", default=bench_framework.DEFAULT_CACHE)
    parser.add_argument("--output", default=None, help="write the figures as JSON")
    parser.add_argument("--save", default=None, help="directory for the selection tables")
    parser.add_argument(
        "--reference-tables",
        default=None,
        help="saved tables of an earlier reference run to compare with (see bench_framework)",
    )
    args = parser.parse_args(argv)
    results = {"n_jobs": args.n_jobs, "versions": _versions()}
    print("== EM ==")
    results["em"] = bench_em.main(["--repeats", "3"])
    print("\n== prediction ==")
    results["predict"] = bench_predict.main([])
    if not args.skip_framework:
        print("\n== selection framework ==")
        results["framework"] = bench_framework.run(
            7,
            n_jobs=args.n_jobs,
            cache=args.cache,
            reference=not args.skip_reference,
            save=args.save,
            reference_tables=args.reference_tables,
        )
    print("\n== memory ==")
    results["memory"] = bench_memory.measure()
    print(
        f"peak {results['memory']['peak_mb']:.0f} MB resident for "
        f"{results['memory']['rows']:,} rows x {results['memory']['dims']} columns"
    )
    ok = summarise(results)
    if args.output:
        with open(args.output, "w") as out:
            json.dump(results, out, indent=1, default=str)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
