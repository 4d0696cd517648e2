"""The simulator's human run: a virtual driver keeps the lane of a section, the logger
measures what happened (:func:`make_lane_keeping`)."""

import os

import numpy as np

from ..._core._compat import HasMethods, StrOptions, validate_params
from ._closed_loop import LOG_COLUMNS
from ._driver import DRIVER_STYLES, DriverParameters
from ._section import Section, SectionSpec
from ._sensors import measure

#: What ``cache`` may be: a folder, a ``joblib.Memory`` (or anything with its ``cache``), None.
CACHE = [str, os.PathLike, HasMethods(["cache"]), None]


def human_run(spec, driver, recording=None, split="train", law=None):
    """The tidy frame of a human of ``driver``'s style (or parameters) driving the section of
    ``spec`` (a :class:`SectionSpec`), as :func:`make_lane_keeping` returns it.

    ``law`` (a tuple of the remnants the law keeps, of :data:`._driver.REMNANTS`; ``()``
    none) adds the column ``law_torque`` [Nm]: at every sample, the torque of the human's
    control law without its other remnants, run on the states of the recording (see
    :func:`._closed_loop.simulate`'s ``law_log``), less the arms' damping and inertia on
    the steering wheel's motion, which a rigid column's torque sensor reads (exact; with a
    torsion bar the sensor reads it less the upper wheel's inertia torque). Its error on
    the clean ``driver_torque`` of a rigid column is the torque of the remnants it does not
    keep.
    """
    section = Section(spec, driver)
    law_log = None if law is None else np.empty(section.n_samples)
    log = section.simulate(law_log=law_log, law_keeps=law or ())
    features, torque = section.features(log)
    # sensors: drawn after the closed loop, which therefore does not depend on sensor_noise
    features, torque = measure(
        features, torque, 1.0 / spec.sampling_rate, section.speed, spec.sensor_scale, section.rng
    )
    style = driver if isinstance(driver, str) else "custom"
    if recording is None:
        recording = spec.recording_of(style)
    frame = section.frame(log, features, torque, recording=recording, driver=style, split=split)
    if law is not None:
        wheel = dict(zip(LOG_COLUMNS, log.T, strict=True))
        arms = section.parameters.arm_damping * wheel["theta_d"]
        frame["law_torque"] = law_log - arms - section.parameters.arm_inertia * wheel["theta_dd"]
    return frame


@validate_params(
    {
        "driver": [StrOptions(set(DRIVER_STYLES)), DriverParameters],
        "recording": [str, None],
        "split": [str],
        "cache": CACHE,
    }
    | SectionSpec.constraints(),
    prefer_skip_nested_validation=True,
)
def make_lane_keeping(
    duration=300.0,
    *,
    setting=7,
    driver="defensive",
    speed_kmh=100.0,
    sampling_rate=100.0,
    scenario="highway",
    random_state=None,
    road_random_state=None,
    recording=None,
    split="train",
    sensor_noise="typical",
    vehicle=None,
    perturbation=None,
    cache=None,
):
    """Simulate a driver keeping the centre lane of a pseudo-random highway section.

    A closed-loop simulation (thesis Appendices B and C.1) of a virtual driver that steers with
    torque (preview, reaction delay, internal model of the steering feel, neuromuscular lag,
    coloured remnant), a steering system with power assist and self-aligning torque, and a
    single-track vehicle with tyre saturation and roll, on a road of straights and circular
    arcs joined by clothoids (Table B.1), three lanes of 3.5 m, at constant speed.

    Parameters
    ----------
    duration : float, default=300.0
        Length of the recording [s]. A section holds at most 5,000,000 integration steps
        (about 7 hours at 100 Hz) and 1000 km of road: simulate longer drives as several.
    setting : int, default=7
        Radius setting of Table B.1: 1 S (300-600 m), 2 M (600-900), 3 L (900-1200),
        4 SM (300-900), 5 ML (600-1200), 6 SL (300-600 and 900-1200), 7 SML (300-1200).
    driver : str or DriverParameters, default="defensive"
        A key of :data:`DRIVER_STYLES` ("defensive", "aggressive", "novice") or parameters.
        Each recording draws its own parameters around the style's (per-recording variability).
    speed_kmh : float, default=100.0
        Constant forward speed [km/h], at least 5 (the thesis drives at 100 km/h).
    sampling_rate : float, default=100.0
        Logging rate [Hz]. The model is integrated at a multiple of it, at least 200 Hz.
    scenario : {"highway", "sharp_corners", "lane_change", "evasive", "wide_lane"}, \
default="highway"
        "highway" is the thesis' protocol. Stress scenarios (thesis Appendix E.4):
        "sharp_corners" uses radii of 175-300 m (25 m grid) instead of the setting's;
        "lane_change" moves to a neighbouring lane and back every 300-800 m; "evasive" adds
        sudden 2.5-3.5 m double lane changes over 30-40 m; "wide_lane" is one 5 m lane of
        straights (300-800 m) alternating with sinusoidal segments (1-4 m amplitude, tightest
        radius 300-600 m; the setting is not used), where the driver's tolerated band and
        corner cut grow with the lane. The lateral deviation stays measured from the centre
        lane.
    random_state : int, RandomState instance or None, default=None
        Seeds the road, the driver parameters and the remnant noise. Same int, same DataFrame.
    road_random_state : int, RandomState instance or None, default=None
        Seeds the road (and the manoeuvres) separately, so that several drivers can drive the
        same section; by default the road is drawn from ``random_state``.
    recording : str, default=None
        Recording id; defaults to ``"{driver}-{scenario}-s{setting}"``.
    split : str, default="train"
        Value of the ``split`` column.
    sensor_noise : {"typical", "none"}, float or None, default="typical"
        Measurement of the logged signals (see Sensors below). "typical": realistic sensor
        errors, derivatives computed from the measured signals, as a vehicle logs them. None or
        "none": the true states of the simulation. A float scales every error (noise, drift,
        resolution; "typical" is 1.0), times the car's ``sensor_noise``. The closed loop always
        runs on the true states.
    vehicle : None, "default", int, dict or VehicleParameters, default=None
        The car and its steering system (friction, power assist, column damping, inertia,
        steering ratio, trails, sensor set). None or "default": the reference car of
        :class:`VehicleParameters`; an int: the car :func:`draw_vehicle` draws from that seed,
        within :data:`VEHICLE_RANGES`; a dict: the reference car with these parameters
        replaced (``{"wheel_friction": 0.6}``). The car is drawn apart from ``random_state``:
        the same seeds give the same road, driver and noises in every car. The driver knows
        the car (its internal model is the car's).
    perturbation : float or None, default=None
        A perturbation experiment: the RMS [Nm] of a torque on the steering wheel that the
        driver does not know (a multisine over 0.05-5 Hz, see Perturbation below), logged in
        the column ``steering_perturbation``. None: no experiment and no such column (0 logs
        a column of zeros).
    cache : str, path or joblib.Memory, default=None
        Cache the simulation on disk (only used when ``random_state`` is an int and
        ``road_random_state`` an int or None).

    Returns
    -------
    frame : pandas.DataFrame
        One row per sample: ``recording, driver, setting, split, time``, ``manoeuvre`` (what
        the driver is doing: ``"lane_keeping"``, ``"lane_change_left"``,
        ``"lane_change_right"`` or ``"evasive"``, by the car's position on the road) and
        ``crossing_time`` (on the rows of a manoeuvre, the time [s] at which the car's centre
        crosses a marking of the centre lane; NaN elsewhere or if it never does), then the 18
        candidate features :data:`FEATURE_NAMES` (Table B.2) then ``driver_torque`` (the
        driver's), and with ``perturbation`` ``steering_perturbation`` [Nm]. SI units,
        listed in ``frame.attrs["units"]``; ``frame.attrs["lane_width"]`` is the lane's width,
        ``frame.attrs["vehicle"]`` the car's parameters (a dict of :class:`VehicleParameters`).
        Signs: y and yaw to the left; roll positive when the body leans right (outwards in a
        left turn); deviations are vehicle minus road (lateral at the front axle, heading at
        the road sensors at 0, 10 and 30 m ahead of the front axle);
        curvature positive in left turns.

    Notes
    -----
    Calibration. Over one 5-minute setting-7 section, every style stays within these bands
    (:data:`CALIBRATION_BANDS`, checked by the tests; thesis Table C.2 in brackets): RMS torque
    1-2.5 Nm (1.64-1.67), max torque 2.5-8 Nm (4.1-4.3), RMS lateral deviation 0.05-0.6 m
    (0.41-0.47), max lateral deviation below 1.75 m (1.1-1.5; the vehicle centre never leaves
    the lane), RMS lateral acceleration 0.5-1.5 m/s^2 (0.97-1.0), RMS steering-wheel angle
    4-12 deg (6.9-7.1), max 10-40 deg (22.8-24.7). Use :func:`calibration_table` to compute them.
    The bands hold for the true states and for the measured signals, in the reference car.

    Sensors (``sensor_noise="typical"``). The driver sees the world, the logger measures it:
    the sensor errors are drawn after the simulation and do not change the closed loop. Each
    measured signal gets white noise (per sample, at the logging rate), a slowly varying error
    (first-order Gauss-Markov: bias, attitude drift, camera tracking error) and a quantisation.
    Magnitudes typical of the sensor type (RMS; 1 deg = 0.01745 rad):

    ===============================  ======================  ==========  ===============  =========
    signal                           sensor type             white       drift (time)     step
    ===============================  ======================  ==========  ===============  =========
    steering wheel angle             steering angle sensor   0.02 deg    -                0.1 deg
    lateral velocity (slip angle)    GNSS/INS or optical     0.03 m/s    -                -
    lateral acceleration             MEMS accelerometer      0.05 m/s^2  0.02 m/s^2 (60)  -
    yaw rate                         MEMS gyro               0.1 deg/s   0.03 deg/s (60)  -
    roll angle                       INS attitude            0.01 deg    0.05 deg (20 s)  -
    lateral deviation 0 m            lane camera             0.01 m      0.03 m (0.2 s)   -
    heading deviation 0 / 10 / 30 m  lane camera             3/4/6e-4    1/1.5/3e-3 rad   -
                                                             rad         (0.2 s)
    road curvature 0 / 10 / 30 m     lane camera             3/4/6e-5    1/1.5/3e-4 1/m   -
                                                             1/m         (0.3 s)
    driver torque (target)           EPS torque sensor       0.03 Nm     -                0.01 Nm
    ===============================  ======================  ==========  ===============  =========

    The slip angle is ``arctan(measured lateral velocity / speed)``. The derivatives are not
    measured but computed as an ECU would, causally: backward difference of the measured signal
    then a first-order low-pass of time constant 20 ms (steering-wheel velocity, from the angle)
    or 40 ms (steering-wheel acceleration from the filtered velocity, yaw acceleration from the
    yaw rate, roll velocity from the roll angle, roll acceleration from the filtered roll
    velocity). At 100 Hz on a setting-7 section, the RMS error (noise and filter lag) is about
    a quarter of the signal RMS for the steering-wheel velocity, half for the roll velocity,
    equal for the yaw acceleration and 3 times for the roll acceleration; the steering-wheel
    acceleration of the model has most of its power above the 4 Hz of the filter, so its
    measured version keeps mainly the low-frequency part (correlation about 0.4).

    Perturbation (``perturbation=``). In a recording of ordinary driving the wheel moves only
    as the driver turns it, so that the data cannot tell the driver's arms from the steering
    system's load. As in neuromuscular-admittance experiments, a torque the driver cannot
    predict is added to the driver's at the steering wheel: a multisine of up to 24 sines of
    equal amplitude at frequencies spread evenly on a log scale over 0.05-5 Hz, each a whole
    number of periods over the section (so that its RMS over the logged rows is
    ``perturbation``), with uniformly drawn phases. Its random stream is its own: an int
    ``random_state`` gives the road, driver, noises and sensor errors of the run without it.
    The steering system cannot tell it from the driver's torque (the assist boosts it, a
    torsion bar carries it); the driver feels it only through the wheel's motion: the arms'
    stiffness, damping and inertia resist at once, the eyes after the reaction time. The
    column ``driver_torque`` is the driver's own share (the torque sensor's reading less the
    perturbation, which the experiment knows), ``steering_perturbation`` the perturbation,
    exact (an applied, not a measured signal). A tenth of the driver's torque RMS (0.1-0.25
    Nm) moves the wheel by a few tenths of a degree without changing how the car is driven.

    Examples
    --------
    >>> from skhmmgmr.datasets import make_lane_keeping
    >>> frame = make_lane_keeping(duration=10.0, driver="aggressive", random_state=0)
    >>> frame.shape
    (1000, 26)
    >>> frame.attrs["units"]["driver_torque"]
    'Nm'
    """
    spec = SectionSpec.of(locals(), "make_lane_keeping")
    run = cached(cache) if cache is not None and spec.seeded else human_run
    return run(spec, driver, recording, split)


def cached(cache):
    """:func:`human_run` cached on disk by ``cache`` (a folder or a joblib.Memory)."""
    from joblib import Memory

    if isinstance(cache, (str, os.PathLike)):
        cache = Memory(os.fspath(cache), verbose=0)
    return cache.cache(human_run)
