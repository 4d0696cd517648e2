"""The data protocol of the thesis (Appendix B.4): training, validation and test sections."""

import math
from dataclasses import asdict, replace
from numbers import Integral, Real

import numpy as np
from joblib import Parallel, delayed
from sklearn.utils import check_random_state

from ..._core._compat import FiniteInterval, Interval, validate_params
from .._frame import concat_frames
from ._driver import DRIVER_STYLES
from ._lane_keeping import CACHE, cached, human_run
from ._section import SectionSpec

TRAIN_SETTINGS = (1, 2, 3, 4, 5, 6)
EVALUATION_SETTING = 7
_COUNT = [Interval(Integral, 0, None, closed="left")]


def _perturbed(sections, share):
    """Whether each section is perturbed: ``share`` of the training sections, spread evenly
    over them (the k-th when ``(k + 1) * share`` reaches the next whole number)."""
    flags, k = [], 0
    for split, _, _ in sections:
        flags.append(split == "train" and math.floor((k + 1) * share) > math.floor(k * share))
        k += split == "train"
    return flags


def protocol_sections(n_train_per_setting, n_validation, n_test):
    """(split, setting, index) of every section of one driver, in protocol order."""
    sections = [
        ("train", setting, i) for setting in TRAIN_SETTINGS for i in range(n_train_per_setting)
    ]
    sections += [("validation", EVALUATION_SETTING, i) for i in range(n_validation)]
    sections += [("test", EVALUATION_SETTING, i) for i in range(n_test)]
    return sections


def protocol_runs(template, drivers, sections, random_state, perturbed_share):
    """The recordings of the protocol, in order: ``(spec, driver, recording, split)`` for
    every driver (a style name) and section of :func:`protocol_sections`, ``spec`` being
    ``template`` (a :class:`SectionSpec`) with the section's setting, seeds and perturbation
    (``template.perturbation`` in ``perturbed_share`` of the training sections, 0 in the
    others, None without an experiment)."""
    rng = check_random_state(random_state)
    high = np.iinfo(np.int32).max
    road_seeds = rng.randint(high, size=len(sections))
    driver_seeds = rng.randint(high, size=(len(drivers), len(sections)))
    unperturbed = None if template.perturbation is None else 0.0
    perturbed = _perturbed(sections, perturbed_share)
    runs = []
    for d, driver in enumerate(drivers):
        for k, (split, setting, i) in enumerate(sections):
            spec = replace(
                template,
                setting=setting,
                random_state=int(driver_seeds[d, k]),
                road_random_state=int(road_seeds[k]),
                perturbation=template.perturbation if perturbed[k] else unperturbed,
            )
            runs.append((spec, driver, f"{driver}-{split}-s{setting}-{i}", split))
    return runs


@validate_params(
    {
        "drivers": [str, "array-like"],
        "n_train_per_setting": _COUNT,
        "n_validation": _COUNT,
        "n_test": _COUNT,
        "random_state": ["random_state"],
        "n_jobs": [Integral, None],
        "cache": CACHE,
        "perturbed_share": [FiniteInterval(Real, 0, 1, closed="both")],
    }
    | SectionSpec.constraints(
        "duration",
        "sampling_rate",
        "speed_kmh",
        "scenario",
        "sensor_noise",
        "vehicle",
        "perturbation",
    ),
    prefer_skip_nested_validation=False,
)
def make_driving_protocol(
    drivers=("defensive", "aggressive", "novice"),
    *,
    n_train_per_setting=2,
    n_validation=6,
    n_test=6,
    duration=300.0,
    sampling_rate=100.0,
    speed_kmh=100.0,
    scenario="highway",
    random_state=None,
    sensor_noise="typical",
    vehicle=None,
    perturbation=None,
    perturbed_share=1.0,
    n_jobs=None,
    cache=None,
):
    """Simulate the thesis' driving protocol for several virtual drivers.

    Per driver: ``n_train_per_setting`` training sections on each of the settings 1-6 of
    Table B.1, then ``n_validation`` validation and ``n_test`` test sections on setting 7
    (defaults: 12, 6 and 6 sections of 5 minutes, as in the thesis). Every driver drives the same
    road sections; driver parameters and remnant noise differ per recording.

    Parameters
    ----------
    drivers : sequence of str, default=("defensive", "aggressive", "novice")
        Keys of :data:`DRIVER_STYLES`.
    n_train_per_setting : int, default=2
        Training sections per setting 1-6.
    n_validation : int, default=6
        Validation sections (setting 7).
    n_test : int, default=6
        Test sections (setting 7).
    duration : float, default=300.0
        Length of every section [s].
    sampling_rate : float, default=100.0
        Logging rate [Hz].
    speed_kmh : float, default=100.0
        Constant forward speed [km/h].
    scenario : str, default="highway"
        Scenario of every section, see :func:`make_lane_keeping`.
    random_state : int, RandomState instance or None, default=None
        Seeds the roads and the recordings.
    sensor_noise : {"typical", "none"}, float or None, default="typical"
        Sensor errors of every recording, see :func:`make_lane_keeping` (Sensors).
    vehicle : None, "default", int, dict or VehicleParameters, default=None
        The car every recording is driven in, see :func:`make_lane_keeping`: None is the
        reference car, an int the car :func:`draw_vehicle` draws from it. The car is drawn
        apart from ``random_state``: the same seed gives the same roads and drivers in every
        car.
    perturbation : float or None, default=None
        A perturbation experiment in ``perturbed_share`` of the training recordings: the RMS
        [Nm] of a torque on the steering wheel that the driver does not know (see
        :func:`make_lane_keeping`, Perturbation). The frame then has the column
        ``steering_perturbation``, 0 in the other recordings; the validation and test
        recordings are never perturbed (a model is tested on ordinary driving). None: no
        experiment and no such column.
    perturbed_share : float in [0, 1], default=1.0
        The share of the training recordings perturbed, spread evenly over the settings
        (``1/3`` of 12: the 3rd, 6th, 9th and 12th); their number is rounded down,
        ``floor(perturbed_share * n_train)`` (0.3 of 12 perturbs 3, any share below
        ``1/n_train`` none). A recording keeps its seeds whether it
        is perturbed or not, and one that is not is the recording of the protocol without
        ``perturbation``.
    n_jobs : int, default=None
        Recordings simulated in parallel (joblib); None means 1.
    cache : str, path or joblib.Memory, default=None
        Disk cache of the recordings, see :func:`make_lane_keeping`.

    Returns
    -------
    frame : pandas.DataFrame
        All recordings, one after the other (rows of a recording contiguous and in time order),
        with ``split`` in {"train", "validation", "test"} and recording ids like
        ``"defensive-train-s1-0"`` or ``"aggressive-test-s7-5"``.

    Examples
    --------
    >>> from skhmmgmr.datasets import make_driving_protocol
    >>> frame = make_driving_protocol(
    ...     ("defensive",), n_train_per_setting=1, n_validation=1, n_test=1, duration=5.0,
    ...     random_state=0)
    >>> frame.groupby("split").recording.nunique().to_dict()
    {'test': 1, 'train': 6, 'validation': 1}
    """
    # every section's spec is this one's with its own setting and seeds, checked here once
    template = SectionSpec.of(
        locals(),
        "make_driving_protocol",
        setting=EVALUATION_SETTING,
        random_state=None,
        road_random_state=None,
    )
    if isinstance(drivers, str):
        drivers = (drivers,)
    drivers = tuple(drivers)
    if not drivers:
        raise ValueError("drivers must name at least one driver style.")
    for driver in drivers:
        if driver not in DRIVER_STYLES:
            raise ValueError(
                f"Unknown driver style {driver!r} in drivers; expected keys of DRIVER_STYLES "
                f"{sorted(DRIVER_STYLES)}."
            )
    if len(set(drivers)) != len(drivers):
        raise ValueError(f"drivers must not repeat a style, got drivers={drivers!r}.")
    sections = protocol_sections(n_train_per_setting, n_validation, n_test)
    if not sections:
        raise ValueError(
            "The protocol holds no section: n_train_per_setting, n_validation and n_test are all 0."
        )
    run = human_run if cache is None else cached(cache)
    jobs = protocol_runs(template, drivers, sections, random_state, perturbed_share)
    return concat_frames(
        Parallel(n_jobs=n_jobs)(delayed(run)(*job) for job in jobs),
        attrs={
            "scenario": template.scenario,
            "speed": template.speed,
            "sensor_noise": template.sensor_scale,
            "vehicle": asdict(template.vehicle),
        },
    )
