"""Steering data of the comma2k19 driving dataset, decoded from raw CAN frames.

comma2k19 (comma.ai, MIT licence) is 33 hours of highway commute split into one-minute
segments. Segments of chunks 1 and 2 come from a Toyota RAV4, whose CAN bus carries the
driver's torque on the steering wheel; this module decodes it, together with the steering and
vehicle-motion signals and, on request, the signals that tell who steers (openpilot or the
driver), with openpilot's Toyota DBC (:mod:`._can`); it puts them on a uniform time
grid and can keep the spans the driver steers alone, each as a recording of its own.
"""

import math
import os
import re
import textwrap
from numbers import Real
from pathlib import Path

import numpy as np
from scipy.signal import savgol_filter

from ..._core._compat import FiniteInterval, StrOptions, validate_params
from ..._core._schema import DRIVER, RECORDING, TARGET, TIME
from .._frame import check_rate, tidy_frame
from ._can import can_decoder

BUS = 0
# The panda marks the frames the comma device sent (openpilot's commands) with bit 7 of the bus.
SENT = 128
DRIVER_NAME = "comma2k19"
TORQUE_UNIT = "raw sensor units"
FLAG_UNIT = "flag (0 or 1)"
_SMOOTHING_SECONDS = 0.25
STEERING = ("all", "driver")

# Messages read on bus 0, the car's bus, where the EPS, brake and engine ECUs send them.
_STEERING_MESSAGES = ("STEER_TORQUE_SENSOR", "KINEMATICS", "STEER_ANGLE_SENSOR")
_ENGAGEMENT_MESSAGES = ("EPS_STATUS", "PCM_CRUISE", "BRAKE_MODULE")
# openpilot's steering command, sent by the comma device; absent when openpilot did not run.
_COMMAND = "STEERING_LKA"
# Engagement column -> (message, signal, unit), held from the last frame at or before a grid time.
ENGAGEMENT = {
    "cruise_active": ("PCM_CRUISE", "CRUISE_ACTIVE", FLAG_UNIT),
    "openpilot_steer_request": (_COMMAND, "STEER_REQUEST", FLAG_UNIT),
    "openpilot_steer_command": (_COMMAND, "STEER_TORQUE_CMD", "raw command units"),
    "eps_lka_active": ("EPS_STATUS", "LKA_STATE", FLAG_UNIT),
    "steer_override": ("STEER_TORQUE_SENSOR", "STEER_OVERRIDE", FLAG_UNIT),
    "brake_pressed": ("BRAKE_MODULE", "BRAKE_PRESSED", FLAG_UNIT),
    "gas_pressed": ("PCM_CRUISE", "GAS_RELEASED", FLAG_UNIT),
}
_RAW_CAN = ("processed_log", "CAN", "raw_can")
_SPEED = ("processed_log", "CAN", "speed")
_REQUIRED_FILES = tuple(Path(*_RAW_CAN, name) for name in ("t", "address", "src", "data")) + (
    Path(*_SPEED, "t"),
    Path(*_SPEED, "value"),
)

ROUTE_PATTERN = re.compile(
    r"^(?P<dongle>[0-9a-f]{16})(?:\||_|--)(?P<start>\d{4}-\d\d-\d\d--\d\d-\d\d-\d\d)$"
)


def _segment_name(path):
    route = path.parent.name
    match = ROUTE_PATTERN.match(route)
    if match:
        route = f"{match['dongle']}|{match['start']}"
    return f"{route}--{path.name}"


def check_sampling_rate(sampling_rate):
    """Return ``sampling_rate`` (a positive finite number) as a float, refusing a rate above
    1000 Hz."""
    return check_rate(
        sampling_rate,
        why="the CAN messages of comma2k19 come at 50 to 83 Hz, so a faster grid only "
        "interpolates, while its rows and smoothing window grow with the rate (a one-minute "
        "segment at 100 kHz takes minutes and about 1 GB).",
    )


_KINDS = {"fiu": "numbers", "iu": "integers", "S": "byte strings"}


class DamagedSegmentError(ValueError):
    """A file of a segment is unreadable, of the wrong type, shape or length, or holds times
    that are not finite or go back."""


class SegmentFiles:
    """The arrays of a segment folder, checked, with the file and segment named in any error."""

    def __init__(self, path):
        self.path = path

    def fail(self, name, problem):
        raise DamagedSegmentError(
            f"The file {name} of the comma2k19 segment {str(self.path)!r} {problem}."
        )

    def read(self, name):
        """The array of the file ``name`` (a path relative to the segment), unchecked."""
        return np.load(self.path / name, allow_pickle=False)

    def load(self, name, kinds, *, length_of=None, column=False):
        """Load the array of the file ``name``; check its dtype kind, shape and length.

        ``length_of`` is the (file name, array) it must have as many values as; ``column``
        also allows one column of shape (n, 1).
        """
        try:
            array = self.read(name)
        except (ValueError, EOFError) as exc:
            self.fail(name, f"is not a readable NumPy array (truncated or damaged?): {exc}")
        if not isinstance(array, np.ndarray) or array.dtype.kind not in kinds:
            dtype = getattr(array, "dtype", type(array).__name__)
            self.fail(name, f"holds {dtype} values instead of {_KINDS[kinds]}")
        if array.ndim != 1 and not (column and array.ndim == 2 and array.shape[1] == 1):
            self.fail(name, f"holds an array of shape {array.shape}, not one value per time")
        if length_of is not None and len(array) != len(length_of[1]):
            self.fail(
                name,
                f"has {len(array)} values, but {length_of[0]} has {len(length_of[1])}: the "
                "files of the segment do not match",
            )
        return array.reshape(len(array))

    def times(self, name, *, monotonic=True):
        """Load the finite times of the file ``name``, checked never to go back if asked."""
        times = self.load(name, "fiu").astype(float)
        bad = np.flatnonzero(~np.isfinite(times))
        if bad.size:
            self.fail(name, f"holds a time that is not finite at index {bad[0]}")
        return self.check_order(name, times) if monotonic else times

    def check_order(self, name, times, *, index=None, of=""):
        """Refuse times that go back; ``index`` gives their positions in the file."""
        back = np.flatnonzero(np.diff(times) < 0)
        if back.size:
            i = int(back[0]) + 1
            self.fail(
                name,
                f"has times{of} that go back at index {i if index is None else index[i]} "
                f"({times[i - 1]:.10g} s, then {times[i]:.10g} s; {back.size} step(s) back in "
                "all): the file is damaged, and sorting it would pair the times with the wrong "
                "values",
            )
        return times


def _read_frames(segment, decoder, messages):
    """The decoded signals of ``messages``: message -> (times, {signal: values}), or None for an
    openpilot command the segment does not have."""
    folder = "/".join(_RAW_CAN)
    times = segment.times(f"{folder}/t", monotonic=False)
    length_of = f"{folder}/t", times
    address = segment.load(f"{folder}/address", "iu", length_of=length_of)
    bus = segment.load(f"{folder}/src", "iu", length_of=length_of)
    data = segment.load(f"{folder}/data", "S", length_of=length_of)
    if data.dtype.itemsize > 8:
        segment.fail(f"{folder}/data", f"holds {data.dtype} values: CAN payloads have 8 bytes")
    frames = {}
    for name in messages:
        message, on = decoder.frame_id(name), SENT if name == _COMMAND else BUS
        selected = np.flatnonzero((bus == on) & (address == message))
        if name == _COMMAND and not selected.size:
            frames[name] = None
            continue
        if selected.size < 2:
            raise ValueError(
                f"The segment {segment.path} has no {name} frames (CAN id {message:#x}) on bus "
                f"{on}. Only the Toyota RAV4 segments of comma2k19 (chunks 1 and 2) can be "
                "decoded."
            )
        # The frames of each message must be in time order (the whole file is, in comma2k19).
        of = f" of {name} frames (CAN id {message:#x})"
        segment.check_order(f"{folder}/t", times[selected], index=selected, of=of)
        frames[name] = times[selected], decoder.decode(name, data[selected])
    return frames


def check_options(sampling_rate, *, engagement=False, steering="all", min_span=2.0):
    """Check the options of :func:`load_comma2k19_segment` before any file is read, beyond
    their :data:`LOADER_CONSTRAINTS` (the sampling rate's bound for this source, the extra
    they need); return the sampling rate and the minimum span as floats.

    Raises ImportError when they need openpilot's DBC and ``skhmmgmr[can]`` is not installed.
    """
    sampling_rate = check_sampling_rate(sampling_rate)
    can_decoder(need_dbc=bool(engagement) or steering == "driver")
    return sampling_rate, float(min_span)


# The options of both comma2k19 loaders (the folder's and the bundled sample's), written once:
# their constraints (for the loaders' validate_params; the fetcher's, but for the recording
# id), and their description, put in each docstring in place of its line "{loader options}".
FRAME_CONSTRAINTS = {
    "sampling_rate": [FiniteInterval(Real, 0, None, closed="neither")],
    "eps_torque": ["boolean"],
    "engagement": ["boolean"],
    "steering": [StrOptions(set(STEERING))],
    "min_span": [FiniteInterval(Real, 0, None, closed="left")],
}
LOADER_CONSTRAINTS = FRAME_CONSTRAINTS | {"recording": [str, None]}
LOADER_OPTIONS_DOC = """\
sampling_rate : float, default=20.0
    Rate of the output time grid, in Hz, at most 1000. The CAN messages come at about 50 Hz
    (torque) and 83 Hz (steering, kinematics): a higher rate interpolates, it does not add
    information.
recording : str, default=None
    Recording id of the rows; by default the segment name ``route--segment``, for example
    ``"b0c9d2329ad1606b|2018-08-02--08-34-47--40"``.
eps_torque : bool, default=False
    Whether to add the torque measured by the power-steering motor (``eps_torque``, raw
    units). It results from the driver's torque and the assistance, so it is left out by
    default.
engagement : bool, default=False
    Whether to add the columns that tell who steers (see Notes), decoded with openpilot's
    DBC: needs ``skhmmgmr[can]``.
steering : {"all", "driver"}, default="all"
    ``"driver"`` keeps only the rows where the driver steers alone: openpilot requests no
    steering torque and the power steering applies none (``openpilot_steer_request`` and
    ``eps_lka_active`` both 0). Each run of such rows lasting at least ``min_span`` becomes
    a recording of its own, ``"<recording>/span<k>"`` (k = 0, 1, ... in time order), so
    that no filter runs across a removed span; a segment without one gives a frame without
    rows. Needs ``skhmmgmr[can]``.
min_span : float, default=2.0
    Shortest span kept with ``steering="driver"``, in seconds; a span of n rows lasts
    n / ``sampling_rate``."""


def with_loader_options(func):
    """Decorator: put :data:`LOADER_OPTIONS_DOC` in place of the docstring's ``{loader options}``
    line, indented as that line is."""
    lines = []
    for line in func.__doc__.splitlines(keepends=True):
        if line.strip() == "{loader options}":
            indent = line[: len(line) - len(line.lstrip())]
            line = textwrap.indent(LOADER_OPTIONS_DOC, indent) + "\n"
        lines.append(line)
    func.__doc__ = "".join(lines)
    return func


@validate_params(
    {"path": [str, os.PathLike]} | LOADER_CONSTRAINTS, prefer_skip_nested_validation=True
)
@with_loader_options
def load_comma2k19_segment(
    path,
    *,
    sampling_rate=20.0,
    recording=None,
    eps_torque=False,
    engagement=False,
    steering="all",
    min_span=2.0,
):
    """Load the steering signals of one comma2k19 segment on a uniform time grid.

    The driver torque, steering angle and rate, yaw rate and lateral acceleration are decoded
    from the raw CAN frames of bus 0 (the car's bus, where all these messages are; the panda's
    other buses do not carry them), with openpilot's Toyota DBC file read by ``cantools`` when
    the extra ``skhmmgmr[can]`` is installed, else with a built-in copy of its seven steering
    signals: both give the same values. The speed is the processed ``CAN/speed`` signal (mean
    of the four wheel speeds). Every signal is linearly interpolated onto a uniform grid over
    the time span all of them cover, then converted to SI units.

    Angles, rates and accelerations follow ISO 8855: positive to the left (counter-clockwise
    seen from above). The torques keep the sensor's sign, which on the example segment goes
    with the steering angle (positive to the left). The phone IMU is not used: the CAN signals
    measure the same quantities in the car's frame, whereas the phone's axes depend on how it
    was mounted.

    Parameters
    ----------
    path : str or path-like
        Segment folder, such as ``.../b0c9d2329ad1606b|2018-08-02--08-34-47/40`` (the ``|`` of
        the route folder may also be written ``_`` or ``--``).
    {loader options}

    Returns
    -------
    frame : pandas.DataFrame
        One row per grid time: meta columns ``recording``, ``driver`` (``"comma2k19"``),
        ``setting`` (NaN: the simulator's settings do not apply to a real car), ``split``
        (``"unknown"``: comma2k19 defines no train/test split), ``time`` (s, from the first
        grid time of the recording); the features ``steering_wheel_angle`` [rad],
        ``steering_wheel_velocity`` [rad/s], ``steering_wheel_acceleration`` [rad/s^2],
        ``lateral_acceleration`` [m/s^2], ``yaw_rate`` [rad/s], ``yaw_acceleration``
        [rad/s^2], ``speed`` [m/s] (then ``eps_torque`` and the engagement columns, if
        asked); last the target ``driver_torque`` in **raw sensor units, not Nm** (openpilot
        takes more than 100 units for "the driver is steering"). ``attrs["units"]`` gives
        every unit; ``attrs["time_origin"]`` maps each recording id to the device boot time
        [s] of its first row, the clock of the other files of the segment.

    Raises
    ------
    FileNotFoundError
        When the folder or one of the files read is missing.
    ImportError
        When ``engagement`` or ``steering="driver"`` is asked without ``skhmmgmr[can]``.
    ValueError
        Naming the file and the segment, when a file is not a readable NumPy array, has the
        wrong type, shape or length, or holds times that are not finite or go back (they are
        never re-sorted); also when the segment has no Toyota steering frames (or, for the
        engagement columns, no EPS_STATUS, PCM_CRUISE or BRAKE_MODULE frames), or an option
        is out of range.

    Notes
    -----
    The two accelerations are derivatives of the steering rate and yaw rate after a
    Savitzky-Golay smoothing over 0.25 s, computed on the whole segment before any span is
    cut out. The lateral acceleration and yaw rate are the car's own inertial sensor:
    uncalibrated, the yaw rate can be offset by a few tenths of a degree per second, and the
    lateral acceleration includes gravity on a banked road. The lateral velocity and slip angle
    are not given: they cannot be measured with these sensors, only estimated with a vehicle
    model. The vehicle is a 2017 RAV4 (wheelbase 2.65 m, steering ratio 16.88).

    The engagement columns (DBC message.signal; flags are 0.0 or 1.0) hold, at each grid time,
    the value of the last frame at or before it (the first frame's value before it):

    - ``cruise_active``: PCM_CRUISE.CRUISE_ACTIVE, the car's adaptive cruise control is
      engaged; on a Toyota, openpilot is engaged exactly then.
    - ``openpilot_steer_request``: STEERING_LKA.STEER_REQUEST, openpilot asks the power
      steering to apply its torque command; read from the frames the comma device sent
      (bus 128 of the log); 0 throughout when the segment has none.
    - ``openpilot_steer_command``: STEERING_LKA.STEER_TORQUE_CMD, that command, in the raw
      units of the power steering (0 when there is no frame).
    - ``eps_lka_active``: EPS_STATUS.LKA_STATE is "active", the power steering applies the
      lane-keeping torque (else "standby", or a fault).
    - ``steer_override``: STEER_TORQUE_SENSOR.STEER_OVERRIDE, the power steering's own flag
      "driver torque above a threshold". openpilot's "steering pressed" is instead
      ``abs(driver_torque) > 100``.
    - ``brake_pressed``: BRAKE_MODULE.BRAKE_PRESSED, the driver presses the brake pedal.
    - ``gas_pressed``: PCM_CRUISE.GAS_RELEASED is 0, the driver presses the accelerator (as
      openpilot reads it).

    A driver overriding openpilot (``steer_override`` set while ``eps_lka_active``) does not
    count as steering alone for ``steering="driver"``: openpilot's torque still acts then.

    The DBC file is ``toyota_new_mc_pt_generated``, the one openpilot uses for the 2017-18
    RAV4, as generated by the ``opendbc`` package (https://github.com/commaai/opendbc, MIT
    licence, Copyright (c) 2020, Comma.ai, Inc.; 0.3.1 is its first release with the Toyota
    files, for Python 3.11 and 3.12). It is read with ``cantools``. Without the extra
    ``skhmmgmr[can]``, the seven steering signals are decoded with a built-in copy of their
    definitions; the engagement options then raise an ImportError.

    Examples
    --------
    >>> from skhmmgmr.datasets import load_comma2k19_segment
    >>> df = load_comma2k19_segment("comma2k19/b0c9d2329ad1606b|2018-08-02--08-34-47/40")
    ... # doctest: +SKIP
    >>> df.attrs["units"]["driver_torque"]  # doctest: +SKIP
    'raw sensor units'
    """
    sampling_rate, min_span = check_options(
        sampling_rate, engagement=engagement, steering=steering, min_span=min_span
    )
    path = Path(path)
    if not path.is_dir():
        raise FileNotFoundError(f"No comma2k19 segment folder at {str(path)!r}.")
    missing = [str(path / f) for f in _REQUIRED_FILES if not (path / f).is_file()]
    if missing:
        raise FileNotFoundError(
            f"The comma2k19 segment folder {str(path)!r} lacks the file(s) {', '.join(missing)}."
        )
    recording = _segment_name(path.resolve()) if recording is None else str(recording)
    return segment_frame(
        SegmentFiles(path),
        recording,
        sampling_rate=sampling_rate,
        eps_torque=eps_torque,
        engagement=engagement,
        steering=steering,
        min_span=min_span,
    )


def segment_frame(segment, recording, *, sampling_rate, eps_torque, engagement, steering, min_span):
    """The frame of :func:`load_comma2k19_segment` from the arrays of ``segment`` (a folder or
    an archive), the options already checked by :func:`check_options`."""
    need_dbc = bool(engagement) or steering == "driver"
    path = segment.path
    decoder = can_decoder(need_dbc=need_dbc)
    messages = _STEERING_MESSAGES
    if need_dbc:
        messages += (*_ENGAGEMENT_MESSAGES, _COMMAND)
    frames = _read_frames(segment, decoder, messages)
    signals = {
        "steering_wheel_angle": _signal(
            frames, "STEER_ANGLE_SENSOR", "STEER_ANGLE", "STEER_FRACTION"
        ),
        "steering_wheel_velocity": _signal(frames, "STEER_ANGLE_SENSOR", "STEER_RATE"),
        "yaw_rate": _signal(frames, "KINEMATICS", "YAW_RATE"),
        "lateral_acceleration": _signal(frames, "KINEMATICS", "ACCEL_Y"),
        "speed": _read_signal(segment, _SPEED),
        TARGET: _signal(frames, "STEER_TORQUE_SENSOR", "STEER_TORQUE_DRIVER"),
    }
    if eps_torque:
        signals["eps_torque"] = _signal(frames, "STEER_TORQUE_SENSOR", "STEER_TORQUE_EPS")

    start = max(t[0] for t, _ in signals.values())
    stop = min(t[-1] for t, _ in signals.values())
    n_samples = int(np.floor((stop - start) * sampling_rate + 1e-9)) + 1
    window = max(5, 2 * int(round(_SMOOTHING_SECONDS * sampling_rate / 2)) + 1)
    if stop <= start or n_samples < window:
        raise ValueError(
            f"The signals of the segment {str(path)!r} overlap on {max(stop - start, 0):.3f} s "
            f"only: too short for a grid at {sampling_rate} Hz."
        )
    grid = start + np.arange(n_samples) / sampling_rate
    on_grid = {name: np.interp(grid, t, v) for name, (t, v) in signals.items()}

    deg = np.pi / 180.0
    columns = {
        RECORDING: recording,
        DRIVER: DRIVER_NAME,
        TIME: grid - start,
        "steering_wheel_angle": on_grid["steering_wheel_angle"] * deg,
        "steering_wheel_velocity": on_grid["steering_wheel_velocity"] * deg,
    }
    columns["steering_wheel_acceleration"] = _derivative(
        columns["steering_wheel_velocity"], sampling_rate, window
    )
    # ACCEL_Y is positive to the right: it anticorrelates with speed * yaw rate.
    columns["lateral_acceleration"] = -on_grid["lateral_acceleration"]
    columns["yaw_rate"] = on_grid["yaw_rate"] * deg
    columns["yaw_acceleration"] = _derivative(columns["yaw_rate"], sampling_rate, window)
    columns["speed"] = on_grid["speed"]
    if eps_torque:
        columns["eps_torque"] = on_grid["eps_torque"]
    flags = _engagement(frames, decoder, grid) if need_dbc else {}
    if engagement:
        columns.update(flags)
    columns[TARGET] = on_grid[TARGET]
    origins = {recording: float(start)}
    if steering == "driver":
        alone = (flags["openpilot_steer_request"] == 0) & (flags["eps_lka_active"] == 0)
        min_rows = max(1, math.ceil(min_span * sampling_rate - 1e-9))
        columns, origins = _driver_spans(columns, alone, grid, sampling_rate, min_rows)
    # setting and split keep the defaults (NaN, "unknown"): comma2k19 defines neither.
    units = {"speed": "m/s", "eps_torque": TORQUE_UNIT, TARGET: TORQUE_UNIT}
    units.update({name: unit for name, (_, _, unit) in ENGAGEMENT.items()})
    return tidy_frame(columns, units=units, attrs={"time_origin": origins})


def _signal(frames, message, *names):
    """(times, values) of the sum of the signals ``names`` of ``message``."""
    times, decoded = frames[message]
    values = decoded[names[0]]
    for name in names[1:]:
        values = values + decoded[name]
    return times, values


def _engagement(frames, decoder, grid):
    """The engagement columns on the grid, each held from the last frame at or before."""
    flags = {}
    for column, (message, signal, _) in ENGAGEMENT.items():
        if frames[message] is None:  # openpilot sent no steering command in this segment
            flags[column] = np.zeros(len(grid))
            continue
        times, decoded = frames[message]
        last = np.maximum(np.searchsorted(times, grid, side="right") - 1, 0)
        flags[column] = decoded[signal][last]
    active = decoder.choice("EPS_STATUS", "LKA_STATE", "active")
    flags["eps_lka_active"] = (flags["eps_lka_active"] == active).astype(float)
    flags["gas_pressed"] = (flags["gas_pressed"] == 0).astype(float)
    return flags


def _driver_spans(columns, alone, grid, sampling_rate, min_rows):
    """Keep the runs of at least ``min_rows`` rows where ``alone``, each a recording of its own,
    its time from 0; return the columns and the boot time of each recording's first row."""
    edges = np.flatnonzero(np.diff(np.concatenate(([0], alone.astype(np.int8), [0]))))
    spans = [(a, b) for a, b in zip(edges[::2], edges[1::2], strict=True) if b - a >= min_rows]
    names = [f"{columns[RECORDING]}/span{k}" for k in range(len(spans))]
    rows = np.concatenate([np.arange(a, b) for a, b in spans] or [np.zeros(0, dtype=int)])
    kept = {name: v if np.ndim(v) == 0 else np.asarray(v)[rows] for name, v in columns.items()}
    kept[RECORDING] = np.repeat(np.array(names, dtype=object), [b - a for a, b in spans])
    kept[TIME] = np.concatenate([np.arange(b - a) / sampling_rate for a, b in spans] or [[]])
    return kept, {n: float(grid[a]) for n, (a, _) in zip(names, spans, strict=True)}


def _read_signal(segment, parts):
    folder = "/".join(parts)
    times = segment.times(f"{folder}/t")
    values = segment.load(f"{folder}/value", "fiu", length_of=(f"{folder}/t", times), column=True)
    return times, values


def _derivative(values, sampling_rate, window):
    return savgol_filter(values, window, polyorder=2, deriv=1, delta=1.0 / sampling_rate)
