"""What the closed-loop benchmarks share: the held-out roads and a regressor as a driver.

``bench_closed_loop.py`` and ``bench_driver_model.py`` drive the same roads (so that their
tables compare) and put scikit-learn regressors that are not the package's at the wheel one
sensed row at a time.
"""

from skhmmgmr.datasets import DRIVER_STYLES, FEATURE_NAMES


def road_seed(style, setting, seed):
    """The seed of the held-out road of ``style`` on ``setting`` for the benchmark's ``seed``:
    every style, setting and seed its own road."""
    return 10_000 + 1_000 * seed + 10 * setting + list(DRIVER_STYLES).index(style)


class OneRow:
    """A fitted scikit-learn regressor of the sensed ``columns`` (all of
    :data:`FEATURE_NAMES` by default), as a driver: one sensed row to a torque."""

    def __init__(self, model, columns=FEATURE_NAMES):
        self.model, self.__name__ = model, type(model).__name__
        self.positions = [list(FEATURE_NAMES).index(c) for c in columns]

    def __call__(self, row):
        return float(self.model.predict(row[self.positions][None, :])[0])
