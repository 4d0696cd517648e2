"""Closed loop with any driver at the wheel: a human style of the simulator, a fitted model of
the package, or any function from one sensed row to a torque."""

import math
import warnings

import numpy as np
import pandas as pd

from .._core._schema import FEATURE_NAMES
from ._driver import DRIVER_STYLES
from ._fmu_driver import FMUDriver, is_fmu
from ._sensors import SensorStream, draw_errors
from ._simulator import (
    LOST_CONTROL,
    Section,
    _features,
    checked_section_arguments,
    make_lane_keeping,
)

# The human whose parameters a model run draws (and does not use): every style draws as many
# numbers, so the road, the manoeuvres and the sensor errors are those of any human's run.
_UNUSED_HUMAN = "defensive"


def drive(
    driver,
    *,
    setting=7,
    duration=300.0,
    sampling_rate=100.0,
    speed_kmh=100.0,
    scenario="highway",
    random_state=None,
    road_random_state=None,
    sensor_noise="typical",
    recording=None,
    split="test",
    vehicle=None,
):
    """Put a driver at the wheel of the simulator and record the drive.

    The closed loop of :func:`make_lane_keeping` (road, steering system with power assist,
    single-track vehicle) with ``driver`` steering. A model drives on what the logger records:
    at every sample it gets the 18 sensed features (with the sensor errors of
    ``sensor_noise``), and its torque acts at the steering wheel until the next sample, as a
    torque feedback actuator would apply it. Same seeds, same road, same manoeuvres and same
    sensor errors for every driver, so that runs compare row by row with the human's.

    Parameters
    ----------
    driver : str, fitted estimator, path-like or callable
        Who drives:

        - a style of :data:`DRIVER_STYLES` (``"defensive"``, ``"aggressive"``, ``"novice"``):
          the human run that :func:`make_lane_keeping` makes for the same seeds;
        - a fitted model of the package (an :class:`~skhmmgmr.HMMGMRRegressor` or a torque
          pipeline; anything with ``filter_stream()``): streamed sample by sample, its inputs
          found by name among the sensed features (``feature_names_in_``);
        - another fitted scikit-learn regressor (anything with ``predict``): called on one row
          at a time, its inputs found by name likewise;
        - a callable ``driver(row) -> torque``, ``row`` an array of the 18 sensed features in
          the order of :data:`FEATURE_NAMES` (read-only), called once per sample in time order;
        - a co-simulation FMU, FMI 2.0 or 3.0 (a path-like, or a string ending in ``.fmu``;
          :func:`skhmmgmr.export.write_fmu` writes them), run through FMPy (the extra
          ``skhmmgmr[fmu]``): its inputs found by name among the sensed features, one
          communication step of ``1 / sampling_rate`` per sample (the FMU's default step size
          must be that), its torque the output ``driver_torque`` (else its first real
          output). Its drive is that of the model it was written from, to round-off.
    setting, duration, sampling_rate, speed_kmh, scenario : see :func:`make_lane_keeping`
    random_state, road_random_state : see :func:`make_lane_keeping`
        The same values give the same road, manoeuvres and sensor errors for every driver.
    sensor_noise : {"typical", "none"}, float or None, default="typical"
        The errors of what the driver model is given and what the frame holds (see
        :func:`make_lane_keeping`); a human always sees the true states.
    recording : str, default=None
        Recording id; defaults to ``"{driver}-{scenario}-s{setting}"`` (the model's class name,
        the FMU's file name or the callable's name for a model).
    split : str, default="test"
        Value of the ``split`` column.
    vehicle : None, "default", int, dict or VehicleParameters, default=None
        The car, see :func:`make_lane_keeping`. The same seeds in another car give the same
        road, manoeuvres and sensor errors (scaled by the car's ``sensor_noise``).

    Returns
    -------
    frame : pandas.DataFrame
        The frame of :func:`make_lane_keeping`: ``recording, driver, setting, split, time``,
        the 18 sensed features as the model got them, and ``driver_torque``, the torque
        sensor's reading: the driver's torque with a rigid column, the torsion bar's torque
        in a car with a ``column_stiffness`` (see :class:`VehicleParameters`). A model that
        loses control (lateral deviation beyond 10 m) ends the drive there: the frame is
        shorter, and
        ``frame.attrs["lost_control"]`` holds the time [s] (``None`` otherwise).

    See Also
    --------
    skhmmgmr.metrics.lane_keeping_metrics : How well a drive kept the lane.

    Notes
    -----
    A model that fits recorded torque well may not drive. Fitted on the steering system's and
    the vehicle's own states (the steering-wheel angle, the yaw rate, the lateral
    acceleration...), a regression of the driver's torque learns mostly what torque holds the
    wheel where it is (the steering system's inverse, which those states explain best); at the
    wheel that is a positive feedback on the angle, and the car leaves the road within
    seconds. A model of what the driver sees of the road (:data:`PREVIEW_FEATURES`: the lane
    position, the heading and the curvature ahead) drives.

    With clean sensors (``sensor_noise=None``) the steering-wheel acceleration a model gets
    is that of the integration step before the sample (this step's depends on its own
    torque). A model has no arm impedance: it imposes its torque on the steering wheel,
    where a human's arms add stiffness, damping and inertia. With a rigid column that is the
    torque the sensor reads; with a torsion bar the sensor reads the bar, which differs from
    the model's torque by the steering wheel's inertia torque while the wheel accelerates.

    Examples
    --------
    A model of what the driver sees of the road keeps the lane:

    >>> from skhmmgmr import HMMGMRRegressor
    >>> from skhmmgmr.datasets import PREVIEW_FEATURES, drive, make_lane_keeping
    >>> from skhmmgmr.metrics import lane_keeping_metrics
    >>> human = make_lane_keeping(120.0, sampling_rate=50.0, random_state=0)
    >>> model = HMMGMRRegressor(n_states=3, random_state=0).fit(
    ...     human[list(PREVIEW_FEATURES)], human["driver_torque"])
    >>> run = drive(model, duration=30.0, sampling_rate=50.0, random_state=1)
    >>> run.shape, run["driver"].iloc[0]
    ((1500, 26), 'HMMGMRRegressor')
    >>> bool(lane_keeping_metrics(run)["lateral_deviation_max"] < 1.75)
    True
    """
    duration, sampling_rate, speed_kmh, setting, scenario, vehicle = checked_section_arguments(
        duration, sampling_rate, speed_kmh, setting, scenario, sensor_noise, vehicle
    )
    if isinstance(driver, str) and not is_fmu(driver):
        if driver not in DRIVER_STYLES:
            raise ValueError(
                f"Unknown driver style driver={driver!r}; expected one of "
                f"{sorted(DRIVER_STYLES)}, a fitted model, an FMU (a .fmu path) or a callable."
            )
        return make_lane_keeping(
            duration,
            setting=setting,
            driver=driver,
            speed_kmh=speed_kmh,
            sampling_rate=sampling_rate,
            scenario=scenario,
            random_state=random_state,
            road_random_state=road_random_state,
            recording=recording,
            split=split,
            sensor_noise=sensor_noise,
            vehicle=vehicle,
        )
    section = Section(
        duration,
        setting,
        _UNUSED_HUMAN,
        speed_kmh,
        sampling_rate,
        scenario,
        random_state,
        road_random_state,
        vehicle,
    )
    dt = 1.0 / sampling_rate
    scale = section.sensor_scale(sensor_noise)
    errors = None if scale is None else draw_errors(section.n_samples, dt, scale, section.rng)
    sensors = SensorStream(FEATURE_NAMES, errors, dt, section.speed, scale)
    sensed = np.empty((section.n_samples, len(FEATURE_NAMES)))
    fmu = FMUDriver(driver, sampling_rate) if is_fmu(driver) else None
    name, torque_of = (fmu.name, fmu) if fmu is not None else _torque_function(driver)

    def torque_source(row, states):
        sensed[row] = sense(section, sensors, row, states)
        view = sensed[row]
        view.flags.writeable = False
        try:
            torque = torque_of(view)
        finally:
            view.flags.writeable = True
        return _as_torque(torque, name, row / sampling_rate)

    try:
        log = section.simulate(torque_source)
    finally:
        if fmu is not None:
            fmu.close()
    n_driven = log.shape[0]
    # the torque sensor reads the log's torque: the driver's own with a rigid column, the
    # torsion bar's with a compliant one
    torques = np.array([sensors.torque(i, value) for i, value in enumerate(log[:, 13].tolist())])
    if recording is None:
        recording = f"{name}-{scenario}-s{setting}"
    frame = section.frame(
        log,
        dict(zip(FEATURE_NAMES, sensed[:n_driven].T, strict=True)),
        torques,
        recording=recording,
        driver=name,
        split=split,
        scale=scale,
    )
    lost = None if n_driven == section.n_samples else n_driven / sampling_rate
    frame.attrs["lost_control"] = lost
    if lost is not None:
        warnings.warn(
            f"{name} lost control {lost:.2f} s into the drive (lateral deviation beyond "
            f"{LOST_CONTROL:g} m): the frame ends there.",
            UserWarning,
            stacklevel=2,
        )
    return frame


def sense(section, sensors, row, states):
    """The sensed features of logged row ``row`` of ``section``, in the order of
    :data:`FEATURE_NAMES`, from the states a torque source of :func:`_simulate` gets."""
    log = np.array([(*states, 0.0)])
    columns, _ = _features(log, section.road, section.vehicle, section.speed)
    return sensors.features(row, {k: float(v[0]) for k, v in columns.items()})


def _torque_function(driver):
    """``(name, torque_of(row))`` of a model or a callable driver."""
    if hasattr(driver, "filter_stream"):
        stream = driver.filter_stream()
        positions = _input_positions(driver)
        return type(driver).__name__, lambda row: stream.update(row[positions])
    if hasattr(driver, "predict"):
        positions = _input_positions(driver)
        columns = [FEATURE_NAMES[i] for i in positions]

        def predict_one(row):
            return driver.predict(pd.DataFrame([row[positions]], columns=columns))

        return type(driver).__name__, predict_one
    if callable(driver):
        return getattr(driver, "__name__", type(driver).__name__), driver
    raise TypeError(
        f"driver must be a style name, a fitted model, an FMU (a .fmu path) or a callable; "
        f"got {type(driver).__name__}."
    )


def _input_positions(model):
    names = getattr(model, "feature_names_in_", None)
    if names is None:
        raise ValueError(
            f"{type(model).__name__} has no feature_names_in_: fit it on a DataFrame whose "
            f"columns are sensed features ({', '.join(FEATURE_NAMES)}) so that drive can "
            "give it its inputs by name."
        )
    unknown = [str(n) for n in names if n not in FEATURE_NAMES]
    if unknown:
        raise ValueError(
            f"{type(model).__name__} reads {unknown}, which the simulator does not sense; "
            f"it senses {list(FEATURE_NAMES)}."
        )
    return np.array([FEATURE_NAMES.index(n) for n in names])


def _as_torque(value, name, time):
    value = np.asarray(value, dtype=float).ravel()
    if value.size != 1:
        raise ValueError(
            f"The driver {name} returned {value.size} values at {time:.3f} s; one torque is "
            "expected."
        )
    torque = float(value[0])
    if not math.isfinite(torque):
        raise ValueError(
            f"The driver {name} returned a non-finite torque ({torque}) at {time:.3f} s."
        )
    return torque
