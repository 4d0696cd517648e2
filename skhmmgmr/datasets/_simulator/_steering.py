"""The steering system, one integration step at a time: the column (rigid, or a torsion bar
between the steering wheel and the lower column) with its damping, friction and power assist.

Its equations are in :mod:`._vehicle`'s documentation. The closed loop
(:mod:`._closed_loop`) calls :func:`steering_column` once per simulation and then, at every
integration step, the step it returns with the torque at the steering wheel: the driver's
hands (a human's arm torque, or a model's torque at the wheel) acting on the wheel, and the
front tyres' aligning torque acting on the rack. Nothing else enters the column, so that a
torque added at the wheel (a perturbation) is added to ``hand_torque`` where the loop calls
the step.

The assist boosts the torque the sensor read at the step before (its gain frozen over the
step), which keeps the balance of the rigid column ``J_sw theta'' = (1 + gain) T_d - loads``,
``T_d = T_hand - B theta' - J_arm theta''``, linear in ``theta''``: a lagged assist would feed
back the arm inertia and oscillate.
"""

import math

# dt * (velocity slope) / inertia of the steering above which it steps implicitly
STIFF_STEP = 0.5


def steering_column(vehicle, dt, arm_inertia, arm_damping):
    """The column of ``vehicle`` stepped every ``dt`` seconds, with the arms at the wheel.

    Parameters
    ----------
    vehicle : VehicleParameters
        The steering system's parameters.
    dt : float
        The integration step [s].
    arm_inertia, arm_damping : float
        The driver's arms at the wheel [kg m^2], [Nms/rad] (0 for a model, which imposes its
        torque).

    Returns
    -------
    bar_torque : callable or None
        ``bar_torque(theta, theta_d, theta_c, theta_c_d)``: the torsion bar's torque, which
        the torque sensor reads; None for a rigid column, whose sensor reads the driver's
        torque (the step's last output).
    step : callable
        ``step(hand_torque, sensed, aligning, theta_d, theta_c, theta_c_d) -> (theta_dd,
        theta_c, theta_c_d, sensed)``: the steering wheel's acceleration over the step, the
        lower column's angle and velocity after it (unchanged with a rigid column) and the
        torque the sensor reads (the driver's at the wheel with a rigid column, the bar's
        given ``sensed`` with a torsion bar), from the torque at the wheel, the sensor's
        torque of the step before and the aligning torque at the wheel.
    """
    b_sw, fric, fric_v = vehicle.wheel_damping, vehicle.wheel_friction, vehicle.friction_velocity
    g0, g1, a_max = vehicle.assist_gain, vehicle.assist_gain_slope, vehicle.assist_max
    j_sw, j_arm, b_arm = vehicle.wheel_inertia, arm_inertia, arm_damping
    tanh = math.tanh

    def assist_gain(sensed):
        gain = g0 + g1 * abs(sensed)
        if gain * abs(sensed) > a_max:
            gain = a_max / abs(sensed)
        return gain

    if math.isfinite(vehicle.column_stiffness):
        return _torsion_bar(vehicle, dt, j_arm, b_arm, assist_gain)

    # explicit Euler on the steering's velocity terms is stable for dt * slope / inertia < 2;
    # a car past STIFF_STEP (stiff damping, narrow friction band, light wheel) steps them
    # implicitly (the reference car, at 0.41 for 200 Hz, does not)
    stiff = dt * (b_sw + fric / fric_v) / j_sw > STIFF_STEP

    def rigid_step(hand_torque, sensed, aligning, theta_d, theta_c, theta_c_d):
        gain = assist_gain(sensed)
        t_arm = hand_torque - b_arm * theta_d
        sticking = tanh(theta_d / fric_v)
        loads = aligning + b_sw * theta_d + fric * sticking
        if stiff:
            # linearised backward Euler on the velocity terms (damping, friction): stable
            # whatever the friction's slope fric / fric_v against the inertia
            slope = b_sw + (1.0 + gain) * b_arm + fric / fric_v * (1.0 - sticking * sticking)
            theta_dd = ((1.0 + gain) * t_arm - loads) / (j_sw + (1.0 + gain) * j_arm + dt * slope)
        else:
            theta_dd = ((1.0 + gain) * t_arm - loads) / (j_sw + (1.0 + gain) * j_arm)
        return theta_dd, theta_c, theta_c_d, t_arm - j_arm * theta_dd

    return None, rigid_step


def _torsion_bar(vehicle, dt, j_arm, b_arm, assist_gain):
    """The two-inertia column of a finite ``column_stiffness`` (see :func:`steering_column`)."""
    b_sw, fric, fric_v = vehicle.wheel_damping, vehicle.wheel_friction, vehicle.friction_velocity
    k_col, c_col = vehicle.column_stiffness, vehicle.column_damping
    j_up = vehicle.steering_wheel_share * vehicle.wheel_inertia
    j_low = vehicle.wheel_inertia - j_up
    tanh = math.tanh

    def bar_torque(theta, theta_d, theta_c, theta_c_d):
        return k_col * (theta - theta_c) + c_col * (theta_d - theta_c_d)

    def step(hand_torque, sensed, aligning, theta_d, theta_c, theta_c_d):
        # The assist boosts the torsion bar torque:
        #   (J_up + J_arm) theta'' = T_hand - B theta' - T_bar
        #   J_low theta_c'' = (1 + gain) T_bar - aligning - b_sw theta_c' - T_fric
        # stepped by linearised backward Euler on the torsion bar and the velocity terms
        # (stable whatever the column's natural frequency against dt): T_bar at the step's
        # end is t_next + k_e (theta'' - theta_c'').
        gain = assist_gain(sensed)
        sticking = tanh(theta_c_d / fric_v)
        k_e = (k_col * dt + c_col) * dt
        t_next = sensed + k_col * dt * (theta_d - theta_c_d)
        r_up = hand_torque - b_arm * theta_d - t_next
        r_low = (1.0 + gain) * t_next - aligning - b_sw * theta_c_d
        r_low -= fric * sticking
        m_up = j_up + j_arm + b_arm * dt + k_e
        m_low = j_low + (1.0 + gain) * k_e + dt * (b_sw + fric / fric_v * (1.0 - sticking**2))
        det = m_up * m_low - (1.0 + gain) * k_e * k_e
        theta_dd = (m_low * r_up + k_e * r_low) / det
        theta_c_d += dt * (m_up * r_low + (1.0 + gain) * k_e * r_up) / det
        theta_c += dt * theta_c_d
        return theta_dd, theta_c, theta_c_d, sensed

    return bar_torque, step
