"""Closed loop with any driver at the wheel: a human style of the simulator, a fitted model of
the package, or any function from one sensed row to a torque."""

import warnings

import numpy as np

from ..._core._compat import validate_params
from ..._core._schema import FEATURE_NAMES
from ._driver import DRIVER_STYLES
from ._fmu_driver import FMUDriver, is_fmu
from ._lane_keeping import human_run
from ._model_driver import as_torque, torque_function
from ._section import Section, SectionSpec
from ._sensors import SensorStream, draw_errors

# The human whose parameters a model run draws (and does not use): every style draws as many
# numbers, so the road, the manoeuvres and the sensor errors are those of any human's run.
_UNUSED_HUMAN = "defensive"


@validate_params(
    {
        # a style, a fitted model, an FMU or a callable: refused below, naming what it takes
        "driver": "no_validation",
        "recording": [str, None],
        "split": [str],
    }
    | SectionSpec.constraints(),
    prefer_skip_nested_validation=False,
)
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
    perturbation=None,
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
    driver : str, fitted estimator or callable
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

        A pipeline whose velocity filter was made for another sampling period than
        ``1 / sampling_rate`` is refused, as its ``predict`` refuses such rows; a torque that is
        not one real, finite number is refused naming the driver and the time.
    setting, duration, sampling_rate, speed_kmh, scenario : see :func:`make_lane_keeping`
    random_state, road_random_state : see :func:`make_lane_keeping`
        The same values give the same road, manoeuvres and sensor errors for every driver.
    sensor_noise : {"typical", "none"}, float or None, default="typical"
        The errors of what the driver model is given and what the frame holds (see
        :func:`make_lane_keeping`); a human always sees the true states.
    recording : str, default=None
        Recording id; defaults to ``"{driver}-{scenario}-s{setting}"`` (the model's class name
        or the callable's name for a model).
    split : str, default="test"
        Value of the ``split`` column.
    vehicle : None, "default", int, dict or VehicleParameters, default=None
        The car, see :func:`make_lane_keeping`. The same seeds in another car give the same
        road, manoeuvres and sensor errors (scaled by the car's ``sensor_noise``).
    perturbation : float or None, default=None
        A perturbation experiment (see :func:`make_lane_keeping`): the RMS [Nm] of a torque
        on the steering wheel that the driver, human or model, does not know, added to its
        torque and logged in ``steering_perturbation``; the same seeds give the same
        perturbation for every driver.

    Returns
    -------
    frame : pandas.DataFrame
        The frame of :func:`make_lane_keeping`: ``recording, driver, setting, split, time``,
        the 18 sensed features as the model got them, and ``driver_torque``, the torque
        sensor's reading (less the perturbation, if any): the driver's torque with a rigid
        column, the torsion bar's torque in a car with a ``column_stiffness`` (see
        :class:`VehicleParameters`). A model that loses control ends the drive there, with
        a warning: the lateral deviation beyond 10 m, the steering wheel beyond two turns
        either way (past the lock of any car: a model whose torque follows the wheel can
        spin it without bound), or a state that is not finite. The
        frame is then shorter, ``frame.attrs["lost_control"]`` holds the time [s] and
        ``frame.attrs["lost_control_reason"]`` the reason in words (both ``None`` otherwise).

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
    spec = SectionSpec.of(locals(), "drive")
    if isinstance(driver, str) and not is_fmu(driver):
        if driver not in DRIVER_STYLES:
            raise ValueError(
                f"Unknown driver style driver={driver!r}; expected one of "
                f"{sorted(DRIVER_STYLES)}, a fitted model, an FMU (a .fmu path) or a callable."
            )
        return human_run(spec, driver, recording, split)
    fmu = FMUDriver(driver, spec.sampling_rate) if is_fmu(driver) else None
    if fmu is not None:
        name, torque_of = fmu.name, fmu
    else:
        name, torque_of = torque_function(driver, spec.sampling_rate)
    section = Section(spec, _UNUSED_HUMAN)
    dt, scale = 1.0 / spec.sampling_rate, spec.sensor_scale
    errors = None if scale is None else draw_errors(section.n_samples, dt, scale, section.rng)
    sensors = SensorStream(FEATURE_NAMES, errors, dt, section.speed, scale)
    sensed = np.empty((section.n_samples, len(FEATURE_NAMES)))

    def torque_source(row, states):
        sensed[row] = section.sensed(sensors, row, states)
        view = sensed[row]
        view.flags.writeable = False
        try:
            torque = torque_of(view)
        finally:
            view.flags.writeable = True
        return as_torque(torque, f"The driver {name}", row / spec.sampling_rate)

    reasons = []
    try:
        log = section.simulate(torque_source, lost=reasons)
    finally:
        if fmu is not None:
            fmu.close()
    n_driven = log.shape[0]
    # the torque sensor reads the log's torque: the driver's own with a rigid column, the
    # torsion bar's with a compliant one
    torques = np.array([sensors.torque(i, value) for i, value in enumerate(log[:, -1].tolist())])
    frame = section.frame(
        log,
        dict(zip(FEATURE_NAMES, sensed[:n_driven].T, strict=True)),
        torques,
        recording=spec.recording_of(name) if recording is None else recording,
        driver=name,
        split=split,
    )
    lost = None if n_driven == section.n_samples else n_driven / spec.sampling_rate
    frame.attrs["lost_control"] = lost
    frame.attrs["lost_control_reason"] = reasons[0] if reasons else None
    if lost is not None:
        warnings.warn(
            f"{name} lost control {lost:.2f} s into the drive ({reasons[0]}): the frame ends "
            "there.",
            UserWarning,
            stacklevel=2,
        )
    return frame
