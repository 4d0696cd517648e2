"""The derived inputs of a power-assisted steering system: what they are, their names and
units, computed on whole recordings.

The driver torque balances, through the power assist, the steering system's load: the
self-aligning torque of the front tyres, the wheel's inertia and damping, and Coulomb friction.
Two parts of that balance are not linear in any sensed input, and a mixture of local linear
regressions gated by Gaussians can follow them only with many states:

- **friction** switches sign with the steering-wheel velocity over a band of velocities that
  differs from one steering system to the next, from a few thousandths to tenths of a radian
  per second: ``tanh(steering_wheel_velocity / friction_velocity)`` (:func:`friction_input`,
  named ``steering_friction``), or a basis of several bands at once, ``tanh(v / w_j)`` for the
  widths ``w_j`` (:func:`friction_inputs`, named ``steering_friction_<w_j>``), whose
  combination the regression fits: the shape of the friction curve, from the data;
- **friction has a memory**: a column whose friction sticks holds the wheel until the driver
  has turned it far enough to overcome it (through a torsion bar, the bar's twist under the
  friction torque), whatever the velocity; the driver's torque then follows the angle turned
  since the last reversal, the hysteresis of a steering system's torque against its angle.
  A play of half-width ``r`` on the steering-wheel angle (``p_t = clip(p_(t-1), x_t - r, x_t
  + r)``, the elementary operator of rate-independent hysteresis) gives ``(x_t - p_t) / r`` in
  [-1, 1] (:func:`hysteresis_input`, named ``steering_hysteresis_<r>``, a basis of several
  half-widths ``friction_angle``);
- **the steering load is compressed**: the boost curve of an electric power assist grows with
  the torque (the driver's share of a large load is smaller), and the tyres' aligning torque
  saturates with slip. Odd powers of the load's proxies (the steering-wheel angle and the lateral
  acceleration: ``x |x|`` and ``x^3``) are the first terms of any smooth odd curve
  (:func:`load_inputs`, named ``<column>_signed_square``, ``<column>_cube``...).

At high sampling rates the measured velocity is noisy at the scale of the friction band; a
causal first-order filter (:func:`low_pass`, restarted at every recording by
:func:`filtered_velocity`) keeps that noise out of the friction input. The play restarts at
every recording too (:func:`recording_hysteresis`). The stream
(``skhmmgmr/streaming/_derived.py``) and the generated C compute the same inputs one sample
at a time.
"""

import math
import numbers

import numpy as np
from numba import njit
from scipy.signal import lfilter

from ..streaming._derived import check_time_steps

#: The name of the friction input.
FRICTION_NAME = "steering_friction"
#: The prefix of the names of the hysteresis inputs.
HYSTERESIS_NAME = "steering_hysteresis"
#: The prefix of the names of the friction inputs of the slow velocity.
SLOW_FRICTION_NAME = "steering_friction_slow"


def friction_input(velocity, friction_velocity):
    """The friction input ``tanh(velocity / friction_velocity)`` of every row."""
    return np.tanh(velocity / friction_velocity)


def friction_widths(friction):
    """The widths of the friction inputs of ``friction`` (a ``friction_velocity``: one band, a
    tuple of widths or None), as a tuple of floats."""
    if friction is None:
        return ()
    if isinstance(friction, tuple | list):
        return tuple(float(width) for width in friction)
    return (float(friction),)


def friction_names(friction, prefix=FRICTION_NAME):
    """The names of the friction inputs of ``friction``: ``steering_friction`` for one band,
    ``steering_friction_<width>`` (three significant digits) for every width of a basis
    (``prefix`` in place of ``steering_friction``: ``steering_friction_slow`` for those of the
    slow velocity)."""
    if friction is None:
        return []
    if isinstance(friction, tuple | list):
        return [f"{prefix}_{float(width):.3g}" for width in friction]
    return [prefix]


def slow_friction_names(friction, slow):
    """The names of the friction inputs of the slow velocity: those of ``friction`` with the
    prefix ``steering_friction_slow``, none without a slow velocity filter (``slow``)."""
    return [] if slow is None else friction_names(friction, SLOW_FRICTION_NAME)


def friction_inputs(velocity, friction, prefix=FRICTION_NAME):
    """The friction inputs of ``friction`` (see :func:`friction_names`) of every row, by name."""
    names = friction_names(friction, prefix)
    widths = friction_widths(friction)
    return {name: friction_input(velocity, w) for name, w in zip(names, widths, strict=True)}


def power_name(column, power):
    """The name of the signed power ``power`` of the load column ``column``."""
    label = f"x{column}" if isinstance(column, numbers.Integral) else str(column)
    if power == 2:
        return f"{label}_signed_square"
    if power == 3:
        return f"{label}_cube"
    return f"{label}_signed_power{power}"


def load_inputs(values, positions, load_columns, powers):
    """The signed powers ``sign(x) |x|^p`` of the load columns of ``values`` (a 2-D array,
    the columns at ``positions[column]``), by name, every power of a column in turn."""
    derived = {}
    for column in load_columns:
        x = values[:, positions[column]]
        for power in powers:
            derived[power_name(column, power)] = np.sign(x) * np.abs(x) ** power
    return derived


def hysteresis_names(radii):
    """The names of the hysteresis inputs of the half-widths ``radii`` (a tuple, or None):
    ``steering_hysteresis_<r>``, ``r`` to three significant digits."""
    return [f"{HYSTERESIS_NAME}_{float(r):.3g}" for r in radii or ()]


@njit(cache=True)
def _play(values, radius, out):
    """The play of half-width ``radius`` over one recording's ``values`` into ``out``; NaN
    gives NaN and leaves the play alone, the first observed value starts it (output 0)."""
    started = False
    position = 0.0
    for t in range(values.shape[0]):
        x = values[t]
        if not np.isfinite(x):
            out[t] = np.nan
            continue
        if not started:
            position = x
            started = True
        elif position < x - radius:
            position = x - radius
        elif position > x + radius:
            position = x + radius
        out[t] = (x - position) / radius


def hysteresis_input(angle, radius):
    """The hysteresis input ``(x_t - p_t) / radius`` of one recording's angle, the play ``p``
    started at the first observed angle (see the module's docstring)."""
    out = np.empty(len(angle))
    _play(np.ascontiguousarray(angle, dtype=float), float(radius), out)
    return out


def led_angle(angle, velocity, lead):
    """The angle the plays read with ``angle_lead``: ``angle + lead * velocity`` (see
    ``SteeringFeatures``)."""
    return angle + lead * velocity


def recording_hysteresis(angle, layout, radii):
    """The hysteresis inputs of rows in filter order (their recordings' ``layout``), the play
    restarted at every recording, by name."""
    recordings = layout.recordings(len(angle))
    inputs = {}
    for name, radius in zip(hysteresis_names(radii), radii, strict=True):
        column = np.empty(len(angle))
        for start, stop in zip(recordings.starts, recordings.stops, strict=True):
            column[start:stop] = hysteresis_input(angle[start:stop], radius)
        inputs[name] = column
    return inputs


def derived_names(friction, load_columns, powers, radii=None, slow=None):
    """The names of the derived inputs, in their order: the friction inputs of ``friction``
    (a ``friction_velocity``, see :func:`friction_names`), those of the slow velocity (with a
    ``slow_velocity_filter`` ``slow``), the hysteresis inputs of ``radii`` (a
    ``friction_angle``), then the signed powers of every load column."""
    names = friction_names(friction) + slow_friction_names(friction, slow)
    names += hysteresis_names(radii)
    names += [power_name(column, power) for column in load_columns for power in powers]
    return names


def derived_units(units, friction, load_columns, powers, radii=None, slow=None):
    """The units of the input columns (a mapping of names to units, or ``None``) with those of
    the derived inputs added: 1 for the friction inputs of ``friction`` (and of the slow
    velocity, with ``slow``) and the hysteresis inputs of ``radii``, ``(unit)^p`` for the
    power ``p`` of a column with a unit; ``None`` without units."""
    if not isinstance(units, dict):
        return None
    units = dict(units)
    for name in derived_names(friction, (), (), radii, slow):
        units[name] = "1"
    for column in load_columns:
        unit = units.get(column)
        for power in powers:
            name = power_name(column, power)
            if unit is None:
                units.pop(name, None)
            else:
                units[name] = f"({unit})^{power}"
    return units


def filter_decay(sampling_period, time_constant):
    """The velocity filter's factor per row, ``exp(-sampling_period / time_constant)``."""
    return math.exp(-sampling_period / time_constant)


def low_pass(values, decay):
    """One recording through the causal first-order filter ``y_t = decay y_(t-1) + (1 - decay)
    x_t``, started at its first observed value (``y = x`` there).

    A missing value (NaN) gives NaN and leaves the filter's state alone; the next observed
    value ``x`` after ``g`` missing ones is taken in over the ``g + 1`` periods since the last
    observed one, ``y = decay^(g+1) y_last + (1 - decay^(g+1)) x`` (the filter's exact answer to
    ``x`` held over that time), so that a missing sample never spreads.
    """
    filtered = np.full(len(values), np.nan)
    observed = np.flatnonzero(~np.isnan(values))
    if not observed.size:
        return filtered
    # runs of consecutive observed rows
    breaks = np.flatnonzero(np.diff(observed) > 1) + 1
    last = last_row = None
    for run in np.split(observed, breaks):
        x = values[run[0] : run[-1] + 1]
        if last is None:  # the recording's first observed value: y = x
            start = decay * x[0]
        else:  # after a gap of g missing rows, as above; the lfilter adds (1 - decay) x[0]
            lapse = decay ** (run[0] - last_row)
            start = lapse * last + (decay - lapse) * x[0]
        filtered[run[0] : run[-1] + 1] = lfilter([1.0 - decay], [1.0, -decay], x, zi=[start])[0]
        last, last_row = filtered[run[-1]], run[-1]
    return filtered


def filtered_velocity(velocity, layout, sampling_period, time_constant):
    """The velocity of rows in filter order (their recordings' ``layout``) through the
    velocity filter of time constant ``time_constant``, restarted at every recording; a time
    level that steps otherwise than ``sampling_period`` is refused, naming the recording."""
    recordings = layout.recordings(len(velocity))
    if layout.time is not None:
        check_time_steps(np.asarray(layout.time, dtype=float), recordings, sampling_period)
    decay = filter_decay(sampling_period, time_constant)
    filtered = np.empty_like(velocity)
    for start, stop in zip(recordings.starts, recordings.stops, strict=True):
        filtered[start:stop] = low_pass(velocity[start:stop], decay)
    return filtered


def check_widths(widths, parameter, names_of):
    """Refuse a basis (of ``parameter``, whose inputs ``names_of`` names) that is empty, holds
    a width that is not a positive finite number, or two widths of one name."""
    if not widths:
        raise ValueError(f"{parameter}={widths!r} holds no width; give None for no such input.")
    for width in widths:
        if (
            isinstance(width, bool)
            or not isinstance(width, numbers.Real)
            or not math.isfinite(width)
            or width <= 0
        ):
            raise ValueError(
                f"{parameter} must hold widths > 0; got {width!r} in {parameter}={widths!r}."
            )
    names = names_of(tuple(widths))
    if len(set(names)) != len(names):
        raise ValueError(
            f"{parameter}={widths!r} repeats a width (to three significant digits, which "
            f"name the inputs: {names})."
        )


def fitted_friction(friction):
    """A ``friction_velocity`` as the fitted step holds it: a basis as a tuple of floats."""
    if isinstance(friction, tuple | list):
        return friction_widths(friction)
    return friction


def fitted_radii(radii):
    """A ``friction_angle`` as the fitted step holds it: a tuple of floats (or None, "auto")."""
    if isinstance(radii, tuple | list):
        return tuple(float(r) for r in radii)
    if radii is None or isinstance(radii, str):
        return radii
    return (float(radii),)


def fitted_slow(slow, friction):
    """A ``slow_velocity_filter`` as the fitted step holds it: a float, ``"auto"``, or
    ``None`` (no slow velocity, or no friction input to give it)."""
    if slow is None or friction is None:
        return None
    return slow if isinstance(slow, str) else float(slow)


def fitted_lead(lead, radii):
    """An ``angle_lead`` as the fitted step holds it: a float, ``"auto"``, or ``None`` for the
    angle itself (a lead of 0, or no plays)."""
    if lead is None or radii is None or (not isinstance(lead, str) and lead == 0):
        return None
    return lead if isinstance(lead, str) else float(lead)


def check_settings(step):
    """What the constraints of a ``SteeringFeatures``' parameters cannot say: the powers,
    the load columns, the widths and finite numbers."""
    for power in step.powers:
        if not isinstance(power, numbers.Integral) or isinstance(power, bool) or power < 2:
            raise ValueError(
                f"powers must hold integers >= 2 (1 is the input itself); got {power!r} "
                f"in powers={step.powers!r}."
            )
    if len(set(step.powers)) != len(step.powers):
        raise ValueError(f"powers={step.powers!r} repeats a power.")
    if len(set(step.load_columns)) != len(step.load_columns):
        raise ValueError(f"load_columns={step.load_columns!r} repeats a column.")
    if isinstance(step.friction_velocity, tuple | list):
        check_widths(step.friction_velocity, "friction_velocity", friction_names)
    if isinstance(step.friction_angle, tuple | list):
        check_widths(step.friction_angle, "friction_angle", hysteresis_names)
    for name in (
        "friction_velocity",
        "velocity_filter",
        "sampling_period",
        "angle_lead",
        "slow_velocity_filter",
    ):
        value = getattr(step, name)
        real = isinstance(value, numbers.Real) and not isinstance(value, bool)
        if real and not math.isfinite(value):
            raise ValueError(f"{name} must be finite; got {name}={value!r}.")


def source_positions(step):
    """Position of every source column of ``step`` (a ``SteeringFeatures`` in its ``fit`` or
    after), with an error naming the missing ones."""
    needed = list(step.load_columns)
    if step.friction_angle is not None:
        needed.insert(0, step.angle_column)
    led = step.angle_lead is not None and step.friction_angle is not None
    if step.friction_velocity is not None or led:
        needed.insert(0, step.friction_column)
    names = getattr(step, "feature_names_in_", None)
    positions, missing = {}, []
    for column in needed:
        if isinstance(column, str):
            if names is None or column not in names:
                missing.append(column)
            else:
                positions[column] = int(np.flatnonzero(names == column)[0])
        elif isinstance(column, numbers.Integral) and not isinstance(column, bool):
            if column >= step.n_features_in_:
                missing.append(column)
            positions[column] = int(column)
        else:
            raise TypeError(f"columns are names or positions; got {column!r}.")
    if missing:
        where = (
            "X has no column names (pass a DataFrame, or positions for an array)"
            if names is None
            else f"X has columns {list(names)}"
        )
        raise ValueError(
            f"SteeringFeatures needs the column(s) {missing} (friction_column / "
            f"angle_column / load_columns); {where}."
        )
    return positions


def stream_description(step):
    """The plain description a fitted ``SteeringFeatures`` gives of itself for a stream (see
    its ``stream_settings``)."""
    positions = source_positions(step)
    names = getattr(step, "feature_names_in_", None)
    friction, radii, lead = step.friction_velocity_, step.friction_angle_, step.angle_lead_
    slow = step.slow_velocity_filter_
    filtered = friction is not None and step.velocity_filter_ is not None
    if isinstance(friction, tuple):
        friction = list(friction_widths(friction))
    elif friction is not None:
        friction = float(friction)
    return {
        "n_features_in": int(step.n_features_in_),
        "feature_names_in": None if names is None else [str(name) for name in names],
        "feature_names_out": [str(name) for name in step.get_feature_names_out()],
        "friction_position": None if friction is None else positions[step.friction_column],
        "friction_velocity": friction,
        "filter_decay": (
            filter_decay(step.sampling_period_, step.velocity_filter_) if filtered else None
        ),
        "sampling_period": None if step.sampling_period_ is None else float(step.sampling_period_),
        "angle_position": None if radii is None else positions[step.angle_column],
        "friction_angle": None if radii is None else [float(r) for r in radii],
        "angle_lead": None if lead is None else float(lead),
        "slow_filter_decay": (None if slow is None else filter_decay(step.sampling_period_, slow)),
        "lead_position": None if lead is None else positions[step.friction_column],
        "load_positions": [positions[column] for column in step.load_columns],
        "powers": [int(power) for power in step.powers],
    }
