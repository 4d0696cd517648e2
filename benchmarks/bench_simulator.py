"""Simulation speed of the embedded lane-keeping simulator.

Run: ``python benchmarks/bench_simulator.py``. Prints the median wall time of a 5-minute,
100 Hz recording per driver style (target: at most 2 s on a 2-core machine).
"""

import statistics
import time

from skhmmgmr.datasets import DRIVER_STYLES, make_lane_keeping


def main(repeats=5):
    print(f"{'driver style':<14}{'median [s]':>12}{'max [s]':>10}   (300 s at 100 Hz)")
    for style in DRIVER_STYLES:
        seconds = []
        for seed in range(repeats):
            start = time.perf_counter()
            make_lane_keeping(300.0, driver=style, sampling_rate=100.0, random_state=seed)
            seconds.append(time.perf_counter() - start)
        print(f"{style:<14}{statistics.median(seconds):>12.3f}{max(seconds):>10.3f}")


if __name__ == "__main__":
    main()
