"""The closed loop: a driver, the steering system and the vehicle stepped together by
semi-implicit Euler at the integration rate, their states logged at the sampling rate.

At every integration step the driver (:func:`._driver.human_steering`, or a torque source
called at every logged sample) gives the torque at the steering wheel; the vehicle
(:func:`._vehicle.single_track`) gives the tyres' aligning torque and its own rates from the
road wheels' angle; the steering column (:func:`._steering.steering_column`) turns the two
torques into the wheel's acceleration; then every state moves on by one step. The log has
one row per sample, its columns :data:`LOG_COLUMNS`.
"""

import math

import numpy as np

from ._driver import REMNANTS, human_steering
from ._steering import steering_column
from ._vehicle import single_track

LOST_CONTROL = 10.0  # [m] lateral deviation at which the simulation stops
#: [rad] steering-wheel angle at which the simulation stops: two turns either way, past the
#: lock of any car (a model whose torque follows the wheel can spin it without bound while
#: the tyres, saturated, keep the car within the lane's reach).
MAX_WHEEL_ANGLE = 4.0 * math.pi
#: The columns of a simulation's log: the steering wheel's angle, velocity and acceleration,
#: the vehicle's lateral velocity and acceleration, yaw rate and acceleration, roll angle,
#: velocity and acceleration, its arc length along the road, its lateral and heading
#: deviations from the road's centreline, and the torque the torque sensor reads.
LOG_COLUMNS = (
    "theta",
    "theta_d",
    "theta_dd",
    "v",
    "a_y",
    "r",
    "r_d",
    "phi",
    "phi_d",
    "phi_dd",
    "s",
    "e_y",
    "e_psi",
    "torque",
)
#: The logged columns a simulation starts from (``initial``), followed by the sensed torque
#: of the sample before.
INITIAL_COLUMNS = ("theta", "theta_d", "theta_dd", "v", "r", "phi", "phi_d", "s", "e_y", "e_psi")


def simulate(
    section,
    n_samples,
    torque_source=None,
    initial=None,
    column_log=None,
    perturbation=None,
    lost=None,
    law_log=None,
    law_keeps=(),
):
    """Integrate the closed loop of ``section`` for ``n_samples`` samples; return the log,
    an array (n_samples, 14) of :data:`LOG_COLUMNS`.

    ``torque_source``: another driver than the human of ``section.parameters``, called at
    every logged sample as ``torque_source(row, states)`` with the states of the logged
    columns but the torque (the steering-wheel acceleration of the integration step before);
    its torque acts at the steering wheel until the next sample. It may lose control: the log
    then ends at the first sample where the lateral deviation exceeds :data:`LOST_CONTROL`,
    the steering wheel's angle exceeds :data:`MAX_WHEEL_ANGLE` or a state is not finite
    (:func:`lost_control`); a human that does raises a ``RuntimeError``.
    ``lost``: a list to which the reason (:func:`lost_control`) is appended when the torque
    source loses control.

    ``initial`` (with a ``torque_source`` only): start from a logged state instead of rest,
    the values of :data:`INITIAL_COLUMNS` and the sensed torque of the integration step
    before (which sets the power assist's gain), followed, with a torsion bar, by the lower
    column's ``(theta_c, theta_c_d)`` at that sample (from ``column_log``); without them the
    lower column starts at the bar's static twist under that torque, turning with the wheel
    (exact at rest only).
    ``column_log``: an array (n_samples, 2) that receives ``(theta_c, theta_c_d)`` at every
    logged sample (with a torsion bar; the rigid column writes the wheel's angle and velocity).
    ``perturbation``: the torque of a perturbation experiment (:mod:`._perturbation`) at every
    integration step, added to the driver's at the steering wheel; the driver does not know it.
    The logged torque is the torque sensor's, less the perturbation (the driver's share): the
    driver's (the human's, or the torque source's) with a rigid column; the torsion bar's
    ``k_c (theta - theta_c) + c_c (theta' - theta_c')`` at the sample with a
    ``column_stiffness``, ``theta_c`` being the lower column's angle (see :mod:`._vehicle`).
    ``law_log`` (with the human only): an array (n_samples,) that receives at every logged
    sample the torque the human's control law asks at the wheel without its remnants (no
    noise on the desired angle or the torque, no lane wander) but those named in
    ``law_keeps`` (of :data:`._driver.REMNANTS`): a second copy of the law, with its own
    delay line, hold and muscle, fed the states of the run, which the human with all its
    remnants drives (:func:`._driver.human_steering`'s ``hand_torque``).
    """
    vehicle, dt, n_sub, road = section.vehicle, section.dt, section.n_sub, section.road
    if initial is not None and torque_source is None:
        raise ValueError("initial needs a torque_source (a human starts at rest)")
    human, bar_torque, column = _at_the_wheel(section, torque_source, law_log, law_keeps)
    rates = single_track(vehicle, section.speed)
    if perturbation is not None:
        perturbation = np.asarray(perturbation, dtype=float).tolist()
    curv, inv_ds = road.curvature.tolist(), 1.0 / (road.s[1] - road.s[0])
    start = _start(initial, vehicle)
    theta, theta_d, theta_dd, v, r, phi, phi_d, s, e_y, e_psi, sensed, theta_c, theta_c_d = start
    s_d = e_y_d = e_psi_d = t_hand = push = 0.0
    log = np.empty((n_samples, len(LOG_COLUMNS)))
    row = 0
    for k in range(n_samples * n_sub):
        sample = k % n_sub == 0
        if sample:
            states = (theta, theta_d, theta_dd, v, r, phi, phi_d, s, e_y, e_psi)
            if _lost_control_at(k * dt, states, section, human is None, lost):
                return log[:row]
        if human is not None:
            t_hand = human(k, s, e_y, e_psi, s_d, e_y_d, e_psi_d, theta)
        x = s * inv_ds
        i = int(x)
        kappa = curv[i] + (x - i) * (curv[i + 1] - curv[i])
        # tyres, aligning torque, vehicle (none of which depends on this step's torque)
        aligning, v_d, r_d, a_y, phi_dd, s_d, e_y_d = rates(
            theta if bar_torque is None else theta_c, v, r, phi, phi_d, e_y, e_psi, kappa
        )
        if bar_torque is not None:  # the torque sensor reads the torsion bar
            sensed = bar_torque(theta, theta_d, theta_c, theta_c_d)
        if perturbation is not None:
            push = perturbation[k]
        if sample:
            body = (v, a_y, r, r_d, phi, phi_d, phi_dd, s, e_y, e_psi)
            if column_log is not None:  # the lower column with the logged states
                column_log[row] = (theta, theta_d) if bar_torque is None else (theta_c, theta_c_d)
            if human is None:
                states = (theta, theta_d, theta_dd, *body)
                t_hand = torque_source(row, states)
                log[row] = (*states, t_hand if bar_torque is None else sensed - push)
                row += 1
        # the torque at the steering wheel enters the column here, and only here
        theta_dd, theta_c, theta_c_d, sensed = column(
            t_hand if perturbation is None else t_hand + push,
            sensed,
            aligning,
            theta_d,
            theta_c,
            theta_c_d,
        )
        if human is not None and sample:
            log[row] = (theta, theta_d, theta_dd, *body, sensed - push)
            row += 1
        theta_d += dt * theta_dd
        theta += dt * theta_d
        v += dt * v_d
        r += dt * r_d
        phi_d += dt * phi_dd
        phi += dt * phi_d
        s += dt * s_d
        e_y += dt * e_y_d
        e_psi_d = r - kappa * s_d
        e_psi += dt * e_psi_d
    return log


def _at_the_wheel(section, torque_source, law_log, law_keeps):
    """The human's step (None with a ``torque_source``, which has no arm impedance of its
    own), logging its law into ``law_log`` when given (see :func:`simulate`), and the
    steering column's ``(bar_torque, step)`` with the arms at the wheel."""
    vehicle, dt = section.vehicle, section.dt
    if torque_source is not None:
        if law_log is not None:
            raise ValueError("law_log needs the human at the wheel (torque_source=None)")
        return None, *steering_column(vehicle, dt, 0.0, 0.0)
    driver = section.parameters
    column = steering_column(vehicle, dt, driver.arm_inertia, driver.arm_damping)
    at = (driver, vehicle, section.road, section.offsets, section.speed, dt)
    human = human_steering(*at, section.remnants)
    if law_log is None:
        return human, *column
    unknown = sorted(set(law_keeps) - set(REMNANTS))
    if unknown:
        raise ValueError(f"law_keeps names {unknown[0]!r}; the remnants are {REMNANTS}")
    quiet = tuple(
        noise if name in law_keeps else np.zeros_like(noise)
        for name, noise in zip(REMNANTS, section.remnants, strict=True)
    )
    law, n_sub = human_steering(*at, quiet), section.n_sub

    def human_and_law(k, *seen):
        t_law = law(k, *seen)  # the law's state moves on at every step
        if k % n_sub == 0:
            law_log[k // n_sub] = t_law
        return human(k, *seen)

    return human_and_law, *column


def _lost_control_at(time, states, section, model, lost):
    """Whether the loop with ``states`` (of :data:`INITIAL_COLUMNS`) at ``time`` [s] is out of
    control (:func:`lost_control`); a model's (``model``: a torque source) reason goes to
    ``lost``, a human raises."""
    theta, e_y = states[0], states[8]
    # one cheap test (False for a NaN too); the reason only when it fails
    if abs(e_y) <= LOST_CONTROL and abs(theta) <= MAX_WHEEL_ANGLE and math.isfinite(sum(states)):
        return False
    reason = lost_control(dict(zip(INITIAL_COLUMNS, states, strict=True)))
    if not model:
        raise RuntimeError(
            f"The driver lost control {time:.1f} s into the recording ({reason}); "
            f"driver parameters: {section.parameters}."
        )
    if lost is not None:
        lost.append(reason)
    return True


def lost_control(states):
    """Why the closed loop with ``states`` (a mapping of the logged states by their names in
    :data:`LOG_COLUMNS`) is out of control, in words: states that are not finite, the
    steering wheel beyond :data:`MAX_WHEEL_ANGLE`, the lateral deviation beyond
    :data:`LOST_CONTROL`, or a runaway (finite states too large to add up)."""
    bad = [name for name, value in states.items() if not math.isfinite(value)]
    if bad:
        return f"states not finite: {', '.join(bad)}"
    theta, e_y = states["theta"], states["e_y"]
    if abs(theta) > MAX_WHEEL_ANGLE:
        return (
            f"steering wheel at {theta:.3g} rad, beyond {MAX_WHEEL_ANGLE:.3g} rad "
            "(two turns either way)"
        )
    if abs(e_y) > LOST_CONTROL:
        return f"lateral deviation {e_y:.1f} m, beyond {LOST_CONTROL:g} m"
    return "runaway states: " + ", ".join(f"{name}={value:.3g}" for name, value in states.items())


def _start(initial, vehicle):
    """The states the loop starts from: rest, or ``initial`` (see :func:`simulate`), as
    ``INITIAL_COLUMNS``, the sensed torque and the lower column's angle and velocity."""
    if initial is None:
        return (0.0,) * 13
    values = tuple(map(float, initial))
    start = values[:11]
    if not math.isfinite(vehicle.column_stiffness):  # a rigid column has no lower column
        return (*start, 0.0, 0.0)
    if len(values) == 13:
        return values
    # No lower-column state given: the torsion bar's static twist under the logged torque,
    # turning with the wheel (exact at rest only).
    theta, theta_d, sensed = start[0], start[1], start[10]
    return (*start, theta - sensed / vehicle.column_stiffness, theta_d)
