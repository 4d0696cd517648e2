"""Selection for the loop: a scorer that drives the candidate on the simulator's roads.

A model of the driver's torque that estimates recorded torque well may not drive (the user
guide's "The driver model at the wheel"): to rank candidates by how they drive, the
:class:`ClosedLoopScorer` puts each at the wheel of :func:`skhmmgmr.datasets.drive` on a set
of roads, beside the simulator's human on the same roads (same road, manoeuvres and sensor
errors), and scores how far the candidate's lane-keeping metrics
(:func:`skhmmgmr.metrics.lane_keeping_metrics`) are from the human's: per road
``e = |ln(model / human)|``, a drive that loses control counting ``ln 10`` at least (ten
times off), and the score ``-max_roads e`` (or ``-mean``): higher is better, 0 drives as the
human. It is a scikit-learn scorer (``scorer(estimator, X, y)``; the validation rows are not
read), usable in ``GridSearchCV`` beside :class:`~skhmmgmr.PerformanceScore`.

It lives in the selection family, above the datasets and the metrics, which it both needs.
"""

import math
import numbers
import warnings

from .._core._compat import Interval, StrOptions, validate_params
from .._core._pickled import PickleVersionMixin
from ..datasets import DRIVER_STYLES, drive
from ..metrics import lane_keeping_metrics

#: The metrics a closed-loop score compares with the human's (positive for any human drive).
RATIO_METRICS = (
    "lateral_deviation_rms",
    "lateral_deviation_max",
    "heading_error_rms",
    "torque_rms",
    "torque_roughness",
    "steering_reversal_rate",
)
#: The least error of a drive that loses control: ten times off the human.
LOST_CONTROL_ERROR = math.log(10.0)
_SETTINGS = (1, 2, 3, 4, 5, 6, 7)
_ROAD_KEYS = {"setting", "random_state", "road_random_state", "scenario", "speed_kmh"}


class ClosedLoopScorer(PickleVersionMixin):
    """Score a fitted model by how it drives the simulator's roads beside a human.

    Build one with :func:`make_closed_loop_scorer`, which documents the parameters.

    Attributes
    ----------
    roads : list of dict
        The arguments of :func:`~skhmmgmr.datasets.drive` of every road.
    human_ : list of pandas.Series
        The human's lane-keeping metrics on every road, once the scorer has been called.
    """

    def __init__(self, roads, driver, metric, aggregate):
        self.roads, self.driver, self.metric, self.aggregate = roads, driver, metric, aggregate

    def __call__(self, estimator, X=None, y=None, **metadata):
        """The score of ``estimator`` (higher is better, at most 0).

        Parameters
        ----------
        estimator : fitted estimator or callable
            Anything :func:`~skhmmgmr.datasets.drive` takes as a driver: a fitted model of the
            package (streamed), another fitted regressor with ``feature_names_in_`` (called on
            one row at a time), or a function of one sensed row.
        X, y : ignored
            The validation rows of a search; the score reads the drives.
        **metadata : dict
            Ignored (the ``groups`` a search may route).

        Returns
        -------
        score : float
            ``-max`` (or ``-mean``) over the roads of ``|ln(model / human)|`` of the metric
            (the largest over the metrics), ``ln 10`` at least on a road where the model
            lost control.
        """
        errors = self.road_errors(estimator)
        worst = [max(per_metric.values()) for per_metric in errors]
        total = max(worst) if self.aggregate == "worst" else sum(worst) / len(worst)
        return -total

    def road_errors(self, estimator):
        """Per road, ``{metric: |ln(model / human)|}`` (at least ``ln 10`` if it lost control)."""
        humans = self._humans()
        errors = []
        for road, human in zip(self.roads, humans, strict=True):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", UserWarning)  # a loss of control is scored
                frame = drive(estimator, **road)
            metrics = lane_keeping_metrics(frame)
            lost = frame.attrs["lost_control"] is not None
            per_metric = {}
            for name in self.metric:
                error = abs(math.log(max(metrics[name], 1e-300) / human[name]))
                per_metric[name] = max(error, LOST_CONTROL_ERROR) if lost else error
            errors.append(per_metric)
        return errors

    def _humans(self):
        """The human's metrics on every road, driven once."""
        if getattr(self, "human_", None) is None:
            humans = []
            for road in self.roads:
                human = lane_keeping_metrics(drive(self.driver, **road))
                zero = [name for name in self.metric if not human[name] > 0]
                if zero:
                    raise ValueError(
                        f"The human ({self.driver}) has {zero} = 0 on the road {road}: a ratio "
                        "to it is undefined; choose another metric or road."
                    )
                humans.append(human)
            self.human_ = humans
        return self.human_

    def __repr__(self):
        return (
            f"ClosedLoopScorer({len(self.roads)} roads, driver={self.driver!r}, "
            f"metric={self.metric!r}, aggregate={self.aggregate!r})"
        )


@validate_params(
    {
        "roads": [Interval(numbers.Integral, 1, None, closed="left"), list, tuple],
        "driver": [StrOptions(set(DRIVER_STYLES))],
        "metric": [StrOptions(set(RATIO_METRICS)), list, tuple],
        "aggregate": [StrOptions({"worst", "mean"})],
        "duration": [Interval(numbers.Real, 0, None, closed="neither")],
        "sampling_rate": [Interval(numbers.Real, 0, None, closed="neither")],
        "vehicle": "no_validation",  # checked by drive, naming it
        "sensor_noise": "no_validation",  # likewise
    },
    prefer_skip_nested_validation=True,
)
def make_closed_loop_scorer(
    roads=3,
    *,
    driver="defensive",
    metric="lateral_deviation_rms",
    aggregate="worst",
    duration=60.0,
    sampling_rate=100.0,
    vehicle=None,
    sensor_noise="typical",
):
    """A scorer that drives the candidate on the simulator's roads beside a human.

    For model selection by closed-loop behaviour (``GridSearchCV(scoring=...)``, beside
    :class:`~skhmmgmr.PerformanceScore`): the candidate drives every road
    (:func:`skhmmgmr.datasets.drive`) and its lane-keeping metric
    (:func:`skhmmgmr.metrics.lane_keeping_metrics`) is compared with that of the simulator's
    human of style ``driver`` on the same road, same sensor errors:
    ``e = |ln(model / human)|`` per road (``ln 10`` at least where the model lost control),
    the score ``-max`` over the roads (``aggregate="worst"``) or ``-mean``. Higher is better;
    0 is the human's drive.

    Cost per candidate: one drive of every road, ``len(roads) * duration * sampling_rate``
    model updates and the simulator's steps; a 60 s road at 100 Hz takes about 0.5 s with a
    fitted torque pipeline or driver model on one core (a regressor without a stream, called
    one row at a time, is much slower). The human drives once, at the scorer's first call.

    Parameters
    ----------
    roads : int or sequence of dict, default=3
        The roads: an int ``n``, ``n`` roads of the settings 1-7 in turn (setting
        ``1 + 3 i mod 7``: 1, 4, 7, 3...), road ``i`` seeded ``90_000 + i``; or the arguments
        of :func:`~skhmmgmr.datasets.drive` of every road (``setting``, ``random_state``, an
        int, required: the candidates and the human drive the same road; ``road_random_state``,
        ``scenario``, ``speed_kmh``; the others are the scorer's).
    driver : {"defensive", "aggressive", "novice"}, default="defensive"
        The human the candidate is compared with (the style it was trained on).
    metric : str or sequence of str, default="lateral_deviation_rms"
        The metric(s) compared (:data:`RATIO_METRICS`); with several, a road's error is the
        largest of theirs.
    aggregate : {"worst", "mean"}, default="worst"
        Over the roads.
    duration, sampling_rate : float, default=60.0, 100.0
        Of every drive [s], [Hz]: the rate the candidate was fitted at (a pipeline's
        velocity filter refuses another).
    vehicle, sensor_noise
        As for :func:`~skhmmgmr.datasets.drive`.

    Returns
    -------
    scorer : ClosedLoopScorer
        ``scorer(estimator, X, y)`` returns the score.

    Examples
    --------
    >>> from skhmmgmr import HMMGMRRegressor
    >>> from skhmmgmr.datasets import PREVIEW_FEATURES, make_lane_keeping
    >>> from skhmmgmr.selection import make_closed_loop_scorer
    >>> human = make_lane_keeping(60.0, sampling_rate=20.0, random_state=0)
    >>> model = HMMGMRRegressor(n_states=2, random_state=0).fit(
    ...     human[list(PREVIEW_FEATURES)], human["driver_torque"])
    >>> scorer = make_closed_loop_scorer(2, duration=20.0, sampling_rate=20.0)
    >>> score = scorer(model, None)
    >>> bool(-2.0 < score <= 0.0)
    True
    """
    metrics = (metric,) if isinstance(metric, str) else tuple(metric)
    unknown = [name for name in metrics if name not in RATIO_METRICS]
    if unknown or not metrics:
        raise ValueError(
            f"metric must name one or more of {list(RATIO_METRICS)}; got metric={metric!r}."
        )
    common = dict(
        duration=duration, sampling_rate=sampling_rate, vehicle=vehicle, sensor_noise=sensor_noise
    )
    if isinstance(roads, numbers.Integral):
        roads = [
            dict(setting=_SETTINGS[(3 * i) % len(_SETTINGS)], random_state=90_000 + i)
            for i in range(roads)
        ]
    if not roads:
        raise ValueError("roads must hold at least one road.")
    checked = []
    for i, road in enumerate(roads):
        if not isinstance(road, dict) or not set(road) <= _ROAD_KEYS:
            raise ValueError(
                f"roads[{i}] must be a dict of drive's road arguments {sorted(_ROAD_KEYS)}; "
                f"got {road!r}."
            )
        if not isinstance(road.get("random_state"), numbers.Integral):
            raise ValueError(
                f"roads[{i}] needs an int random_state, so that the candidate and the human "
                f"drive the same road; got {road!r}."
            )
        checked.append({**common, **road})
    return ClosedLoopScorer(checked, driver, metrics, aggregate)
