"""Peak resident memory of ``HMMGMRRegressor.fit`` on a large data set.

Fits K=5 on 2.5 million rows x 18 inputs + torque (the issue's size) in a fresh process and
reports the peak resident set size of that process (``VmHWM``), next to the resident size once
the data exist (the user's ``X`` and ``y``, 380 MB) so that the fit's own share is visible. Run::

    python benchmarks/bench_memory.py                  # 2.5M rows, about a minute
    python benchmarks/bench_memory.py --rows 500000    # quick check
"""

import argparse
import json
import resource
import subprocess
import sys


def _status_mb(key):
    with open("/proc/self/status") as status:
        for line in status:
            if line.startswith(f"{key}:"):
                return int(line.split()[1]) / 1024
    return float("nan")


def _peak_mb():
    """Peak resident size of this process's own address space.

    Not ``ru_maxrss``: a child started by vfork + exec (as ``subprocess`` does) inherits in it
    the peak of its parent's address space, so a benchmark run after a large job would report
    the parent's peak instead of the fit's.
    """
    try:
        peak = _status_mb("VmHWM")
    except OSError:  # no /proc: not Linux
        peak = float("nan")
    if peak != peak:  # no VmHWM line either
        peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    return peak


def child(rows, n_inputs, n_states):
    import time

    import numpy as np
    from _data import make_recordings

    from skhmmgmr import HMMGMRRegressor

    X, y, bounds = make_recordings(rows, 84 * max(rows // 500_000, 1), n_inputs, seed=0)
    groups = np.repeat(np.arange(len(bounds) - 1), np.diff(bounds))
    with_data = _status_mb("VmRSS")
    start = time.perf_counter()
    model = HMMGMRRegressor(n_states=n_states, n_iter=10, tol=0.0, random_state=0)
    model.fit(X, y, groups=groups)
    seconds = time.perf_counter() - start
    peak = _peak_mb()
    data_mb = (X.nbytes + y.nbytes + groups.nbytes) / 2**20
    print(
        json.dumps(
            {
                "rows": rows,
                "dims": n_inputs + 1,
                "n_states": n_states,
                "data_mb": data_mb,
                "resident_with_data_mb": with_data,
                "peak_mb": peak,
                "fit_seconds": seconds,
                "n_iter": int(model.n_iter_),
            }
        )
    )


def measure(rows=2_500_000, n_inputs=18, n_states=5):
    """Run the fit in a fresh interpreter and return its figures (a dict)."""
    out = subprocess.run(
        [
            sys.executable,
            __file__,
            "--child",
            "--rows",
            str(rows),
            "--inputs",
            str(n_inputs),
            "--states",
            str(n_states),
        ],
        check=True,
        capture_output=True,
        text=True,
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rows", type=int, default=2_500_000)
    parser.add_argument("--inputs", type=int, default=18)
    parser.add_argument("--states", type=int, default=5)
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child:
        child(args.rows, args.inputs, args.states)
        return
    result = measure(args.rows, args.inputs, args.states)
    print(
        f"{result['rows']:,} rows x {result['dims']} columns, K={result['n_states']}: "
        f"peak {result['peak_mb']:.0f} MB resident (data {result['data_mb']:.0f} MB, "
        f"{result['resident_with_data_mb']:.0f} MB resident before the fit); "
        f"fit {result['fit_seconds']:.1f} s for {result['n_iter']} EM iterations"
    )


if __name__ == "__main__":
    main()
