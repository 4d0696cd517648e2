"""The torque over a horizon, the thesis' way (Appendix E.3): alternate the vehicle model and
the torque estimate.

A human drives a section of the simulator (the run :func:`make_lane_keeping` makes for the
same seeds). A fitted model is streamed along the recording, on the measured rows, sample by
sample; at every start time ``t`` its filter state (the filtered state probabilities of the
past measured rows, the velocity filter of a pipeline) is copied and a *rollout* begins:

1. the simulator's steering system and vehicle start from the true state logged at ``t``
   (``_simulate(initial=...)``), with the model's estimate at ``t`` at the torsion bar;
2. at every following sample, the rollout's states give the features a logger would record
   (the road ahead is known; the sensor errors of the recording carry on,
   ``SensorStream.continue_from``), the copied stream is updated on them, and its estimate is
   the torque of the next sample period, until the largest horizon.

The rollout's torque at ``t + h`` is the estimate of the torque ``h`` seconds ahead, and the
copied stream's state probabilities along the rollout are carried with it. The model's own
stream, and so the starts that follow, never see a rollout.
"""

import copy
from numbers import Integral

import numpy as np
import pandas as pd

from ..._core._compat import HasMethods, Interval, StrOptions, validate_params
from ..._core._schema import FEATURE_NAMES, RECORDING, TARGET, TIME
from ._closed_loop import INITIAL_COLUMNS, LOG_COLUMNS, simulate
from ._driver import DRIVER_STYLES, DriverParameters, check_driver
from ._model_driver import as_torque, model_stream
from ._section import Section, SectionSpec
from ._sensors import SensorStream, draw_errors, measure

HORIZON = "horizon"
ESTIMATE = "estimate"
LOST = "lost_control"
# The logged columns that make the state a rollout starts from (see simulate's ``initial``).
_STATE_COLUMNS = [LOG_COLUMNS.index(name) for name in INITIAL_COLUMNS]


@validate_params(
    {
        "model": [HasMethods(["filter_stream"])],
        "horizons": ["array-like"],
        "driver": [StrOptions(set(DRIVER_STYLES)), DriverParameters],
        "start_every": [Interval(Integral, 1, None, closed="left")],
        "return_proba": ["boolean"],
        "recording": [str, None],
    }
    | SectionSpec.constraints(  # every field but the perturbation, which a rollout never has
        "duration",
        "setting",
        "speed_kmh",
        "sampling_rate",
        "scenario",
        "random_state",
        "road_random_state",
        "sensor_noise",
        "vehicle",
    ),
    prefer_skip_nested_validation=False,
)
def torque_ahead(
    model,
    *,
    horizons=(0.25, 0.5, 1.0, 2.0),
    driver="defensive",
    setting=7,
    duration=60.0,
    sampling_rate=100.0,
    speed_kmh=100.0,
    scenario="highway",
    random_state=None,
    road_random_state=None,
    sensor_noise="typical",
    start_every=1,
    return_proba=False,
    recording=None,
    vehicle=None,
):
    """Estimate the torque over a horizon by alternating the vehicle model and the model.

    The thesis' prediction of the torque ahead (Appendix E.3): from the state at time ``t``
    and the road ahead, the simulator's steering system and vehicle are integrated forward
    with the model's torque as their input, and the model is streamed on the features the
    vehicle's motion produces, until the horizon. A human of the simulator drives the section
    (the recording :func:`make_lane_keeping` makes for the same arguments); the estimates are
    those of its measured torque ``h`` seconds after every start time ``t``.

    Parameters
    ----------
    model : fitted estimator
        A fitted model of the package with ``filter_stream()`` (an
        :class:`~skhmmgmr.HMMGMRRegressor` or a torque pipeline) whose inputs are sensed
        features, found by name (``feature_names_in_``), and one output, as for :func:`drive`
        (a pipeline made for another sampling period is refused likewise).
    horizons : sequence of float, default=(0.25, 0.5, 1.0, 2.0)
        How far ahead [s], each ``>= 0`` and a whole number of sampling periods, all
        different; 0 is the model's filtered estimate at ``t``.
    driver : str or DriverParameters, default="defensive"
        The human who drives the section (see :func:`make_lane_keeping`).
    setting, duration, sampling_rate, speed_kmh, scenario : see :func:`make_lane_keeping`
        The section (default 60 s; every start time costs one rollout).
    random_state, road_random_state, sensor_noise : see :func:`make_lane_keeping`
        The model reads the recording's measured rows up to ``t``, and the rollout's rows
        measured with the recording's sensor errors.
    start_every : int, default=1
        Rows between start times: a rollout starts at rows ``0, start_every, ...`` up to the
        last row whose largest horizon is still in the recording.
    return_proba : bool, default=False
        Also return the state probabilities of the model's stream at ``t + h``.
    recording : str, default=None
        Recording id; defaults to that of :func:`make_lane_keeping`.
    vehicle : None, "default", int, dict or VehicleParameters, default=None
        The car, see :func:`make_lane_keeping`; the rollouts run in the same car.

    Returns
    -------
    result : pandas.DataFrame
        One row per horizon and start time, sorted by horizon then time: ``recording``,
        ``time`` (the start time ``t`` [s], when the estimate is made), ``horizon`` [s],
        ``estimate`` (the model's torque at ``t + horizon`` in the rollout from ``t``),
        ``driver_torque`` (the torque sensor's reading at ``t + horizon`` in the recording),
        ``lost_control`` (the rollout lost control before ``t + horizon``, as in
        :func:`drive`: beyond 10 m, the steering wheel beyond two turns or a state not
        finite; the estimate then holds the last one of the rollout), and with ``return_proba``
        ``state_proba_0`` ... ``state_proba_{n_states-1}``: the filtered state probabilities
        of the model's stream at ``t + horizon`` (at ``t`` for horizon 0).

    See Also
    --------
    skhmmgmr.HMMGMRRegressor.predict_ahead : The forecast of the hidden Markov chain alone.
    shift_target : The target ahead, to fit a model of the torque ahead.
    drive : The model at the wheel for a whole drive.

    Notes
    -----
    The rollout starts from the simulator's true state at ``t`` (in a car, an observer would
    estimate it from the sensors), with the assist's gain at the torque logged the sample
    before. The model's torque acts at the torsion bar as in :func:`drive` (no arm impedance).
    The rollout's rows are measured with the recording's sensor errors at the same rows, so
    that with the human's torque the rollout would log exactly what the recording logs; the
    estimate of a model that drove the section itself is its own torque, at every horizon.

    Examples
    --------
    >>> from skhmmgmr import HMMGMRRegressor
    >>> from skhmmgmr.datasets import PREVIEW_FEATURES, make_lane_keeping, torque_ahead
    >>> human = make_lane_keeping(60.0, sampling_rate=20.0, random_state=0)
    >>> model = HMMGMRRegressor(n_states=3, random_state=0).fit(
    ...     human[list(PREVIEW_FEATURES)], human["driver_torque"])
    >>> ahead = torque_ahead(model, horizons=(0.5, 1.0), duration=10.0, sampling_rate=20.0,
    ...                      start_every=10, random_state=1)
    >>> ahead.shape
    (36, 6)
    >>> ahead.groupby("horizon").size().to_dict()
    {0.5: 18, 1.0: 18}
    """
    spec = SectionSpec.of(locals(), "torque_ahead", perturbation=None)
    parameters = check_driver(driver)
    stream, positions = model_stream(model, spec.sampling_rate)
    who, rate = f"The model {type(model).__name__}", spec.sampling_rate
    n_samples = spec.n_samples
    horizons, rows_ahead = _check_horizons(horizons, rate, n_samples)

    section = Section(spec, parameters)
    column = np.empty((n_samples, 2))  # the lower column's state, for the rollouts
    log = section.simulate(column_log=column)
    sensed, torque, errors = measured_log(section, log)

    n_ahead = max(rows_ahead)
    starts = np.arange(0, n_samples - n_ahead, start_every)
    estimates = np.empty((len(starts), len(rows_ahead)))
    lost = np.zeros(estimates.shape, dtype=bool)
    n_states = stream.state_proba_.shape[0]
    proba = np.empty((*estimates.shape, n_states)) if return_proba else None
    columns = np.array(rows_ahead)
    next_start = 0
    for t in range(starts[-1] + 1):
        estimate = as_torque(stream.update(sensed[t, positions]), who, t / rate)
        if t != starts[next_start]:
            continue
        copied = copy.deepcopy(stream)  # the rollout goes on from the filter state at t
        path, path_proba = _torque_path(
            section, log, column, sensed, errors, t, n_ahead, estimate, copied, positions, who
        )
        estimates[next_start] = path[np.minimum(columns, len(path) - 1)]
        lost[next_start] = columns >= len(path)
        if return_proba:
            proba[next_start] = path_proba[np.minimum(columns, len(path) - 1)]
        next_start += 1

    if recording is None:
        recording = spec.recording_of(driver if isinstance(driver, str) else "custom")
    result = {
        RECORDING: recording,
        TIME: np.tile(starts / rate, len(horizons)),
        HORIZON: np.repeat(horizons, len(starts)),
        ESTIMATE: estimates.T.ravel(),
        TARGET: torque[starts[None, :] + columns[:, None]].ravel(),
        LOST: lost.T.ravel(),
    }
    if return_proba:
        for k in range(n_states):
            result[f"state_proba_{k}"] = proba[:, :, k].T.ravel()
    return pd.DataFrame(result)


def measured_log(section, log):
    """What the logger records of ``log`` (as :func:`make_lane_keeping` measures it): the
    sensed rows (columns in the order of :data:`FEATURE_NAMES`), the measured torque, and the
    sensor errors drawn for them (``None`` without errors), which go on in the rollouts."""
    clean, torque = section.features(log)
    dt, scale = 1.0 / section.sampling_rate, section.spec.sensor_scale
    errors = None
    if scale is not None:
        errors = draw_errors(len(torque), dt, scale, copy.deepcopy(section.rng))
    measured, torque = measure(clean, torque, dt, section.speed, scale, section.rng)
    return np.column_stack([measured[name] for name in FEATURE_NAMES]), torque, errors


def _check_horizons(horizons, sampling_rate, n_samples):
    """The horizons [s] as a float array and in rows; ValueError naming ``horizons``."""
    try:
        values = np.asarray(horizons, dtype=float)
    except (TypeError, ValueError):
        values = None
    if values is None or values.ndim != 1 or values.size == 0:
        raise ValueError(
            f"horizons must be a non-empty sequence of times [s], got horizons={horizons!r}."
        )
    if not np.all(np.isfinite(values)) or np.any(values < 0):
        raise ValueError(f"horizons must be finite and >= 0 [s], got horizons={horizons!r}.")
    rows = values * sampling_rate
    whole = np.round(rows)
    if np.any(np.abs(rows - whole) > 1e-6 * np.maximum(1.0, whole)):
        raise ValueError(
            f"horizons must be whole numbers of sampling periods (1/{sampling_rate:g} s), got "
            f"horizons={horizons!r}."
        )
    if len(set(whole.tolist())) != whole.size:
        raise ValueError(f"horizons must all differ, got horizons={horizons!r}.")
    if whole.max() >= n_samples:
        raise ValueError(
            f"horizons up to {values.max():g} s need a recording longer than that; "
            f"the duration holds {n_samples} samples at {sampling_rate:g} Hz."
        )
    return values, [int(r) for r in whole]


def _torque_path(
    section, log, column, sensed, errors, start, n_ahead, first, stream, positions, who
):
    """The rollout from row ``start`` (``column``: the lower column's logged states): the
    torques of its rows (the first is ``first``) and the state probabilities of ``stream``
    (updated in place) after each; ``who`` names the model in errors."""
    rate, scale = section.sampling_rate, section.spec.sensor_scale
    sensors = SensorStream(FEATURE_NAMES, errors, 1.0 / rate, section.speed, scale)
    sensors.continue_from(dict(zip(FEATURE_NAMES, sensed[start], strict=True)))
    torques = [first]
    proba = [stream.state_proba_]

    def torque_of(row, sensed_row):
        if row == 0:
            return first
        torque = as_torque(stream.update(sensed_row[positions]), who, (start + row) / rate)
        torques.append(torque)
        proba.append(stream.state_proba_)
        return torque

    rollout(section, log, start, n_ahead + 1, sensors, torque_of, column)
    return np.array(torques), np.array(proba)


def rollout(section, log, start, n_rows, sensors, torque_of, column=None):
    """Integrate ``section``'s vehicle from the state logged at row ``start`` of ``log`` for
    ``n_rows`` samples (fewer if it loses control), the torque of every sample period given by
    ``torque_of(row, sensed_row)``: ``row`` counts from 0 at ``start``, ``sensed_row`` is what
    ``sensors`` measure at row ``start + row`` (``None`` at row 0, whose measured row is the
    recording's). ``column``: the lower column's states logged with ``log`` (``column_log``
    of the simulation), which a car with a torsion bar starts from; without it the column
    starts at the bar's static twist. Returns the rollout's log (rows of ``log``'s columns)."""
    previous = log[start - 1, -1] if start > 0 else 0.0
    initial = (*log[start, _STATE_COLUMNS], previous)
    if column is not None:
        initial += tuple(column[start])

    def torque_source(row, states):
        sensed_row = None if row == 0 else section.sensed(sensors, start + row, states)
        return torque_of(row, sensed_row)

    return simulate(section, n_rows, torque_source, initial)
