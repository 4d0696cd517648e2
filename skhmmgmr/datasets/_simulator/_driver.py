"""Virtual drivers that steer with torque (thesis Appendix C.1, Table C.1).

The driver model has two layers.

Visual layer (path following), perceived with a reaction delay: a two-point preview controller
asks for a path curvature from the far point (pure pursuit of the lane target ``preview_time``
seconds ahead, which both anticipates the road curvature and corrects the heading, with a lead
``lead_time`` on its drift) plus a near point correction of the lateral deviation outside a
tolerated band (a soft dead zone of width ``lane_tolerance``), growing with the square of the
deviation (doubled at ``edge_deviation``) as the car nears the lane markings. The lane target
cuts corners towards the inside by ``corner_cutting * lane_tolerance`` at a 300 m radius
(proportional to curvature) and wanders slowly (``lane_wander``, attention). The demanded
curvature becomes a desired steering-wheel angle through the driver's internal model of the
vehicle (``vehicle_model_gain`` times the true steady-state gain). A driver with
``hold_time > 0`` updates this desired angle intermittently (sample and hold), which gives the
step-like corrections of a novice.

Neuromuscular layer (steering feel): the command torque is the feed-forward torque the driver
expects the steering to need at the desired angle (internal model of the aligning torque and the
power assist, scaled by ``feel_gain``) plus the arm stiffness times the desired angle; it passes
through a first-order muscle activation lag. The arm impedance (stiffness on the actual angle,
damping, inertia) acts at the wheel without lag.
Remnant: coloured noise on the desired angle, and on the torque scaled with the control effort.

:func:`human_steering` is the model's step: the driver's torque at the wheel at every
integration step of the closed loop (:mod:`._closed_loop`).
"""

import math
from dataclasses import dataclass, fields, replace

import numpy as np
from scipy.signal import lfilter

from ._road import LANE_WIDTH

CORNER_CUT_RADIUS = 300.0  # [m] radius at which the corner cut is corner_cutting * tolerance
LINE_LIMIT = 0.8  # [m] largest intended offset from the centre of a 3.5 m lane (car 1.8 m wide)


@dataclass(frozen=True)
class DriverParameters:
    """Parameters of a virtual driver of :func:`make_lane_keeping` (``driver=``), in SI units.

    The named styles are :data:`DRIVER_STYLES`; a variant of one is
    ``dataclasses.replace(DRIVER_STYLES["defensive"], reaction_time=0.3)``. The fields follow the
    thesis' driver model (Appendix C.1, Table C.1): a visual layer (reaction, preview and lead
    times, near-point gain, tolerated deviation, corner cutting, the driver's internal model of
    the vehicle), a neuromuscular layer (arm stiffness, damping and inertia, muscle activation
    lag, intermittent updates) and remnants (coloured noise on the angle and the torque, lane
    wander), and ``variability``, the spread of every parameter between recordings.
    """

    reaction_time: float  # [s] perception-to-action delay of the visual layer
    preview_time: float  # [s] far point time ahead (distance = speed * time)
    lead_time: float  # [s] anticipation on the far-point error rate
    near_gain: float  # [1/m^2] curvature per metre of lateral deviation outside the band
    lane_tolerance: float  # [m] tolerated lateral deviation (soft dead zone half-width)
    edge_deviation: float  # [m] deviation at which the near correction doubles (0: constant)
    corner_cutting: float  # [-] lateral shift to the inside, in lane_tolerance at R = 300 m
    vehicle_model_gain: float  # [-] internal steady-state steering gain / true gain
    feel_gain: float  # [-] internal steering-feel torque / true steady-state torque
    arm_stiffness: float  # [Nm/rad] stiffness on the steering-wheel angle error
    arm_damping: float  # [Nms/rad] intrinsic damping of the arms
    arm_inertia: float  # [kg m^2] inertia of the arms at the wheel
    activation_time: float  # [s] first-order muscle activation lag
    hold_time: float  # [s] intermittent update period of the desired angle (0: continuous)
    angle_remnant: float  # [rad] RMS coloured noise on the desired angle
    angle_remnant_time: float  # [s] correlation time of the angle remnant
    torque_remnant: float  # [Nm] RMS coloured torque noise at zero effort
    torque_remnant_effort: float  # [-] extra torque noise per Nm of command torque
    lane_wander: float  # [m] RMS slow drift of the lateral target
    lane_wander_time: float  # [s] correlation time of the drift
    variability: float  # [-] log-normal spread of the parameters between recordings


#: Named driving styles. "defensive" and "aggressive" follow the thesis' IPGDriver presets
#: (Table C.1: corner cutting 0.2 and 0.8, tolerated lateral deviation 0.5 and 1.0 m): the
#: aggressive driver previews further, reacts faster, cuts corners and tolerates more deviation,
#: and so needs slightly less steering angle and torque; the defensive driver lags behind the
#: corners. "novice" reacts late, over-corrects with high gains and updates its steering
#: intermittently (jerky corrections). Each recording draws its own parameters around these.
DRIVER_STYLES = {
    "defensive": DriverParameters(
        reaction_time=0.25,
        preview_time=1.3,
        lead_time=0.1,
        near_gain=0.0015,
        lane_tolerance=0.5,
        edge_deviation=1.5,
        corner_cutting=0.2,
        vehicle_model_gain=0.9,
        feel_gain=0.9,
        arm_stiffness=4.0,
        arm_damping=0.4,
        arm_inertia=0.06,
        activation_time=0.12,
        hold_time=0.0,
        angle_remnant=0.01,
        angle_remnant_time=0.5,
        torque_remnant=0.1,
        torque_remnant_effort=0.05,
        lane_wander=0.35,
        lane_wander_time=6.0,
        variability=0.08,
    ),
    "aggressive": DriverParameters(
        reaction_time=0.18,
        preview_time=1.4,
        lead_time=0.2,
        near_gain=0.001,
        lane_tolerance=1.0,
        edge_deviation=1.5,
        corner_cutting=0.8,
        vehicle_model_gain=0.97,
        feel_gain=1.0,
        arm_stiffness=6.0,
        arm_damping=0.3,
        arm_inertia=0.05,
        activation_time=0.08,
        hold_time=0.0,
        angle_remnant=0.01,
        angle_remnant_time=0.4,
        torque_remnant=0.1,
        torque_remnant_effort=0.05,
        lane_wander=0.25,
        lane_wander_time=6.0,
        variability=0.08,
    ),
    "novice": DriverParameters(
        reaction_time=0.25,
        preview_time=1.3,
        lead_time=0.3,
        near_gain=0.003,
        lane_tolerance=0.3,
        edge_deviation=0.0,
        corner_cutting=0.0,
        vehicle_model_gain=0.9,
        feel_gain=0.7,
        arm_stiffness=8.0,
        arm_damping=0.3,
        arm_inertia=0.07,
        activation_time=0.1,
        hold_time=0.2,
        angle_remnant=0.02,
        angle_remnant_time=0.3,
        torque_remnant=0.2,
        torque_remnant_effort=0.1,
        lane_wander=0.25,
        lane_wander_time=4.0,
        variability=0.1,
    ),
}

# Parameters kept fixed between recordings of a style.
_FIXED = ("variability", "hold_time", "corner_cutting", "edge_deviation")


def check_driver(driver):
    """Return the :class:`DriverParameters` of a style name or of a parameter object."""
    if isinstance(driver, DriverParameters):
        return driver
    if isinstance(driver, str) and driver in DRIVER_STYLES:
        return DRIVER_STYLES[driver]
    raise ValueError(
        f"Unknown driver style driver={driver!r}; expected one of {sorted(DRIVER_STYLES)} "
        "or a DriverParameters instance."
    )


def sample_driver(parameters, rng):
    """Draw the parameters of one recording: each multiplied by a log-normal factor."""
    changes = {}
    for field in fields(parameters):
        if field.name in _FIXED:
            continue
        factor = math.exp(parameters.variability * rng.standard_normal())
        changes[field.name] = getattr(parameters, field.name) * factor
    return replace(parameters, **changes)


def coloured_noise(n, dt, correlation_time, rms, rng):
    """Stationary first-order (Ornstein-Uhlenbeck) noise of given RMS, sampled every ``dt``."""
    white = rng.standard_normal(n + 1)
    if rms <= 0.0:
        return np.zeros(n)
    a = math.exp(-dt / max(correlation_time, dt))
    b = math.sqrt(1.0 - a * a)
    noise, _ = lfilter([b], [1.0, -a], white[1:], zi=[a * white[0]])
    return rms * noise


#: The human's remnants, in the order :func:`draw_remnants` returns them.
REMNANTS = ("angle", "torque", "wander")


def draw_remnants(driver, n_steps, dt, rng):
    """The human driver's coloured noises over ``n_steps`` integration steps: on the desired
    angle, on the torque, and the lane wander (drawn for every driver, so that the sensor
    errors drawn next are the same whoever drives)."""
    return (
        coloured_noise(n_steps, dt, driver.angle_remnant_time, driver.angle_remnant, rng),
        coloured_noise(n_steps, dt, 0.1, driver.torque_remnant, rng),
        coloured_noise(n_steps, dt, driver.lane_wander_time, driver.lane_wander, rng),
    )


def human_steering(driver, vehicle, road, offsets, speed, dt, remnants):
    """The virtual driver's torque at the steering wheel, one integration step at a time.

    Parameters
    ----------
    driver : DriverParameters
        The recording's driver (drawn by :func:`sample_driver`).
    vehicle : VehicleParameters
        The car, which the driver's internal model knows.
    road : Road
        The section; ``offsets`` is the lane target's offset along it (the manoeuvres).
    speed, dt : float
        The car's speed [m/s] and the integration step [s].
    remnants : tuple of ndarray
        :func:`draw_remnants`' noises, one value per integration step.

    Returns
    -------
    hand_torque : callable
        ``hand_torque(k, s, e_y, e_psi, s_d, e_y_d, e_psi_d, theta)``: the driver's torque
        at the wheel at integration step ``k`` (the muscle torque less the arm stiffness
        times the wheel's angle ``theta``, with the torque remnant), seeing the car's arc
        length ``s`` on the road, its lateral and heading deviations and their rates (those
        of the step before). It holds the driver's state: the delay line of the visual layer,
        the desired angle and the muscle's activation, and must be called at every step, in
        order.
    """
    k_arm = driver.arm_stiffness
    act_lag = dt / (driver.activation_time + dt)
    look = speed * driver.preview_time
    far_gain = 2.0 / (look * look)
    lead = driver.lead_time
    # A wider lane leaves the driver more room: the tolerated band, the corner cut and the
    # deviation at which the correction grows scale with the lane's width.
    lane_scale = road.lane_width / LANE_WIDTH
    line_limit = LINE_LIMIT + (road.lane_width - LANE_WIDTH) / 2.0
    near_gain, tol = driver.near_gain, driver.lane_tolerance * lane_scale
    edge = driver.edge_deviation * lane_scale
    inv_edge = 1.0 / edge if edge > 0 else 0.0
    angle_gain = driver.vehicle_model_gain * vehicle.steering_angle_for_curvature(speed)
    feel = driver.feel_gain * vehicle.aligning_stiffness(speed)
    fb0, fb1 = 1.0 + vehicle.assist_gain, vehicle.assist_gain_slope
    n_delay = max(1, int(round(driver.reaction_time / dt)))
    n_hold = int(round(driver.hold_time / dt))
    # Lane target (manoeuvre offset + corner cut) and the far point on the road, tabulated.
    grid = road.s
    cut = driver.corner_cutting * tol * np.clip(road.curvature * CORNER_CUT_RADIUS, -1.5, 1.5)
    far = road.lateral_offset(grid, look) + road.at(offsets, grid + look)
    near, far = offsets.tolist(), far.tolist()
    cut_near, cut_far = cut.tolist(), road.at(cut, grid + look).tolist()
    inv_ds = 1.0 / (grid[1] - grid[0])
    angle_noise, torque_noise, wander = (noise.tolist() for noise in remnants)
    effort = driver.torque_remnant_effort
    tanh, sqrt, copysign = math.tanh, math.sqrt, math.copysign
    delay_line = [0.0] * n_delay
    t_muscle = theta_des = 0.0

    def hand_torque(k, s, e_y, e_psi, s_d, e_y_d, e_psi_d, theta):
        nonlocal t_muscle, theta_des
        x = s * inv_ds
        i = int(x)
        f = x - i
        # the intended line (corner cut + wander) stays within LINE_LIMIT of the lane centre
        line = cut_near[i] + f * (cut_near[i + 1] - cut_near[i]) + wander[k]
        lane = near[i] + f * (near[i + 1] - near[i]) + max(-line_limit, min(line_limit, line))
        line = cut_far[i] + f * (cut_far[i + 1] - cut_far[i]) + wander[k]
        aim = far[i] + f * (far[i + 1] - far[i]) + max(-line_limit, min(line_limit, line))

        # visual layer, acting after the reaction delay; the lead acts on the far-point drift
        e_far = aim - e_y - look * e_psi
        e_far += lead * ((far[i + 1] - far[i]) * inv_ds * s_d - e_y_d - look * e_psi_d)
        e_near = e_y - lane
        outside = e_near - tol * tanh(e_near / tol)
        outside *= 1.0 + (e_near * inv_edge) ** 2
        theta_vis = angle_gain * (far_gain * e_far - near_gain * outside) + angle_noise[k]
        j = k % n_delay
        delayed = delay_line[j]
        delay_line[j] = theta_vis
        if n_hold == 0 or k % n_hold == 0:
            theta_des = delayed

        # neuromuscular layer: the activation lag acts on the command (expected steering
        # feel plus the equilibrium point of the arm stiffness), the arm impedance at once
        load = feel * theta_des
        t_ff = copysign((sqrt(fb0 * fb0 + 4.0 * fb1 * abs(load)) - fb0) / (2.0 * fb1), load)
        t_muscle += act_lag * (t_ff + k_arm * theta_des - t_muscle)
        t_hand = t_muscle - k_arm * theta
        return t_hand + (1.0 + effort * abs(t_hand)) * torque_noise[k]

    return hand_torque
