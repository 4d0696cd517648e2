"""Steering data of the comma2k19 driving dataset, decoded from raw CAN frames.

comma2k19 (comma.ai, MIT licence) is 33 hours of highway commute split into one-minute
segments. Segments of chunks 1 and 2 come from a Toyota RAV4, whose CAN bus carries the
driver's torque on the steering wheel; this module decodes it, together with the steering and
vehicle-motion signals, with the Toyota DBC definitions.
"""

import numbers
import re
from pathlib import Path
from typing import NamedTuple

import numpy as np
from scipy.signal import savgol_filter

from ._frame import tidy_frame
from ._schema import DRIVER, RECORDING, TARGET, TIME

BUS = 0
DRIVER_NAME = "comma2k19"
TORQUE_UNIT = "raw sensor units"
_SMOOTHING_SECONDS = 0.25
# Grids faster than this only interpolate: the CAN messages decoded come at 50 to 83 Hz.
MAX_SAMPLING_RATE = 1000.0


class CANSignal(NamedTuple):
    """A signal of a CAN message, as a DBC file defines it (big-endian bit order)."""

    address: int
    start_bit: int
    length: int
    signed: bool
    scale: float
    offset: float


# Toyota DBC definitions (openpilot's toyota_*_pt). STEER_FRACTION, the 0.1 deg complement of
# STEER_ANGLE, is needed: the processed CAN/steering_angle of comma2k19 is exactly their sum.
STEER_TORQUE_DRIVER = CANSignal(0x260, 15, 16, True, 1.0, 0.0)
STEER_TORQUE_EPS = CANSignal(0x260, 47, 16, True, 1.0, 0.0)
YAW_RATE = CANSignal(0x24, 1, 10, False, 0.244, -125.0)
ACCEL_Y = CANSignal(0x24, 33, 10, False, 0.03589, -18.375)
STEER_ANGLE = CANSignal(0x25, 3, 12, True, 1.5, 0.0)
STEER_FRACTION = CANSignal(0x25, 39, 4, True, 0.1, 0.0)
STEER_RATE = CANSignal(0x25, 35, 12, True, 1.0, 0.0)

_MESSAGE_NAMES = {0x260: "STEER_TORQUE_SENSOR", 0x24: "KINEMATICS", 0x25: "STEER_ANGLE_SENSOR"}
_RAW_CAN = ("processed_log", "CAN", "raw_can")
_SPEED = ("processed_log", "CAN", "speed")
_REQUIRED_FILES = tuple(Path(*_RAW_CAN, name) for name in ("t", "address", "src", "data")) + (
    Path(*_SPEED, "t"),
    Path(*_SPEED, "value"),
)

ROUTE_PATTERN = re.compile(
    r"^(?P<dongle>[0-9a-f]{16})(?:\||_|--)(?P<start>\d{4}-\d\d-\d\d--\d\d-\d\d-\d\d)$"
)


def decode_big_endian_signal(data, start_bit, length, *, signed=False, scale=1.0, offset=0.0):
    """Decode a big-endian ("Motorola") signal from CAN payloads, for many frames at once.

    Parameters
    ----------
    data : array-like of bytes of shape (n_frames,)
        Payloads of at most 8 bytes (a NumPy ``|S8`` array, or a list of ``bytes``); shorter
        payloads are padded with zero bytes. A ``uint8`` array of shape (n_frames, 8) works too.
    start_bit : int
        Position of the most significant bit of the signal, numbered as a DBC file writes it:
        bit ``8 * k + j`` is bit ``j`` (0 = least significant) of byte ``k``.
    length : int
        Number of bits, 1 to 63.
    signed : bool, default=False
        Whether the raw value is two's complement.
    scale, offset : float, default=1.0, 0.0
        Physical value = raw value * scale + offset.

    Returns
    -------
    values : ndarray of shape (n_frames,)
        The physical values, as floats.

    Examples
    --------
    >>> decode_big_endian_signal([b"\\x00\\xff\\xfe"], start_bit=15, length=16, signed=True)
    array([-2.])
    """
    payload = np.asarray(data)
    if not (payload.dtype == np.uint8 and payload.ndim == 2 and payload.shape[1] == 8):
        if payload.dtype.kind == "O":
            payload = payload.astype("S")
        if payload.dtype.kind != "S" or payload.dtype.itemsize > 8:
            raise ValueError(
                "CAN payloads must be byte strings of at most 8 bytes or uint8 rows of 8 bytes, "
                f"got an array of dtype {payload.dtype}."
            )
        payload = np.frombuffer(payload.astype("S8").tobytes(), dtype=np.uint8).reshape(-1, 8)
    if not 0 <= start_bit < 64 or not 1 <= length < 64:
        raise ValueError(f"Invalid signal: start bit {start_bit}, length {length}.")
    # Byte 0 first makes the payload one big-endian integer, in which the bits of a Motorola
    # signal are contiguous.
    words = np.ascontiguousarray(payload).view(">u8").ravel().astype(np.uint64)
    msb = 8 * (7 - start_bit // 8) + start_bit % 8
    lsb = msb - length + 1
    if lsb < 0:
        raise ValueError(
            f"A {length}-bit signal starting at bit {start_bit} does not fit in 8 bytes."
        )
    raw = ((words >> np.uint64(lsb)) & np.uint64((1 << length) - 1)).astype(np.int64)
    if signed:
        raw = np.where(raw >= 1 << (length - 1), raw - (1 << length), raw)
    return raw * float(scale) + float(offset)


def _decode(frames, signal):
    times, data = frames[signal.address]
    values = decode_big_endian_signal(
        data,
        signal.start_bit,
        signal.length,
        signed=signal.signed,
        scale=signal.scale,
        offset=signal.offset,
    )
    return times, values


def _segment_name(path):
    route = path.parent.name
    match = ROUTE_PATTERN.match(route)
    if match:
        route = f"{match['dongle']}|{match['start']}"
    return f"{route}--{path.name}"


def check_sampling_rate(sampling_rate):
    """Return ``sampling_rate`` as a float, refusing what is not a rate in (0, 1000] Hz."""
    if (
        not isinstance(sampling_rate, numbers.Real)
        or isinstance(sampling_rate, (bool, np.bool_))
        or not np.isfinite(sampling_rate)
        or sampling_rate <= 0
    ):
        raise ValueError(f"sampling_rate must be a positive number of Hz, got {sampling_rate!r}.")
    if sampling_rate > MAX_SAMPLING_RATE:
        raise ValueError(
            f"sampling_rate must be at most {MAX_SAMPLING_RATE:g} Hz, got {sampling_rate!r}: "
            "the CAN messages of comma2k19 come at 50 to 83 Hz, so a faster grid only "
            "interpolates, while its rows and smoothing window grow with the rate (a one-minute "
            "segment at 100 kHz takes minutes and about 1 GB)."
        )
    return float(sampling_rate)


_KINDS = {"fiu": "numbers", "iu": "integers", "S": "byte strings"}


class _Segment:
    """The arrays of a segment folder, checked, with the file and segment named in any error."""

    def __init__(self, path):
        self.path = path

    def fail(self, name, problem):
        raise ValueError(f"The file {name} of the comma2k19 segment {str(self.path)!r} {problem}.")

    def load(self, name, kinds, *, length_of=None, column=False):
        """Load the array of the file ``name``; check its dtype kind, shape and length.

        ``length_of`` is the (file name, array) it must have as many values as; ``column``
        also allows one column of shape (n, 1).
        """
        try:
            array = np.load(self.path / name, allow_pickle=False)
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


def _read_frames(segment):
    folder = "/".join(_RAW_CAN)
    times = segment.times(f"{folder}/t", monotonic=False)
    length_of = f"{folder}/t", times
    address = segment.load(f"{folder}/address", "iu", length_of=length_of)
    bus = segment.load(f"{folder}/src", "iu", length_of=length_of)
    data = segment.load(f"{folder}/data", "S", length_of=length_of)
    if data.dtype.itemsize > 8:
        segment.fail(f"{folder}/data", f"holds {data.dtype} values: CAN payloads have 8 bytes")
    frames = {}
    for message, name in _MESSAGE_NAMES.items():
        selected = np.flatnonzero((bus == BUS) & (address == message))
        if selected.size < 2:
            raise ValueError(
                f"The segment {segment.path} has no {name} frames (CAN id {message:#x}) on bus "
                f"{BUS}. Only the Toyota RAV4 segments of comma2k19 (chunks 1 and 2) can be "
                "decoded."
            )
        # The frames of each message must be in time order (the whole file is, in comma2k19).
        of = f" of {name} frames (CAN id {message:#x})"
        segment.check_order(f"{folder}/t", times[selected], index=selected, of=of)
        frames[message] = times[selected], data[selected]
    return frames


def load_comma2k19_segment(path, *, sampling_rate=20.0, recording=None, eps_torque=False):
    """Load the steering signals of one comma2k19 segment on a uniform time grid.

    The driver torque, steering angle and rate, yaw rate and lateral acceleration are decoded
    from the raw CAN frames of bus 0 (the car's bus, where all these messages are; the panda's
    other buses do not carry them), with the Toyota DBC definitions. The speed is the processed
    ``CAN/speed`` signal (mean of the four wheel speeds). Every signal is linearly interpolated
    onto a uniform grid over the time span all of them cover, then converted to SI units.

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

    Returns
    -------
    frame : pandas.DataFrame
        One row per grid time: meta columns ``recording``, ``driver`` (``"comma2k19"``),
        ``setting`` (NaN: the simulator's settings do not apply to a real car), ``split``
        (``"unknown"``: comma2k19 defines no train/test split), ``time`` (s, from the first
        grid time); the features ``steering_wheel_angle`` [rad],
        ``steering_wheel_velocity`` [rad/s], ``steering_wheel_acceleration`` [rad/s^2],
        ``lateral_acceleration`` [m/s^2], ``yaw_rate`` [rad/s], ``yaw_acceleration``
        [rad/s^2], ``speed`` [m/s] (and ``eps_torque``); last the target ``driver_torque``
        in **raw sensor units, not Nm** (openpilot takes more than 100 units for "the driver
        is steering"). ``attrs["units"]`` gives every unit; ``attrs["time_origin"]`` maps
        the recording id to the device boot time [s] of its first row, the clock of the other
        files of the segment.

    Raises
    ------
    FileNotFoundError
        When the folder or one of the files read is missing.
    ValueError
        Naming the file and the segment, when a file is not a readable NumPy array, has the
        wrong type, shape or length, or holds times that are not finite or go back (they are
        never re-sorted); also when the segment has no Toyota steering frames, or
        ``sampling_rate`` is out of range.

    Notes
    -----
    The two accelerations are derivatives of the steering rate and yaw rate after a
    Savitzky-Golay smoothing over 0.25 s. The lateral acceleration and yaw rate are the car's
    own inertial sensor: uncalibrated, the yaw rate can be offset by a few tenths of a degree
    per second, and the lateral acceleration includes gravity on a banked road. The lateral
    velocity and slip angle are not given: they cannot be measured with these sensors, only
    estimated with a vehicle model. The vehicle is a 2017 RAV4 (wheelbase 2.65 m, steering
    ratio 16.88).

    Examples
    --------
    >>> from skhmmgmr.datasets import load_comma2k19_segment
    >>> df = load_comma2k19_segment("comma2k19/b0c9d2329ad1606b|2018-08-02--08-34-47/40")
    ... # doctest: +SKIP
    >>> df.attrs["units"]["driver_torque"]  # doctest: +SKIP
    'raw sensor units'
    """
    sampling_rate = check_sampling_rate(sampling_rate)
    path = Path(path)
    if not path.is_dir():
        raise FileNotFoundError(f"No comma2k19 segment folder at {str(path)!r}.")
    missing = [str(path / f) for f in _REQUIRED_FILES if not (path / f).is_file()]
    if missing:
        raise FileNotFoundError(
            f"The comma2k19 segment folder {str(path)!r} lacks the file(s) {', '.join(missing)}."
        )
    recording = _segment_name(path.resolve()) if recording is None else str(recording)

    segment = _Segment(path)
    frames = _read_frames(segment)
    signals = {
        "steering_wheel_angle": _sum(_decode(frames, STEER_ANGLE), _decode(frames, STEER_FRACTION)),
        "steering_wheel_velocity": _decode(frames, STEER_RATE),
        "yaw_rate": _decode(frames, YAW_RATE),
        "lateral_acceleration": _decode(frames, ACCEL_Y),
        "speed": _read_signal(segment, _SPEED),
        TARGET: _decode(frames, STEER_TORQUE_DRIVER),
    }
    if eps_torque:
        signals["eps_torque"] = _decode(frames, STEER_TORQUE_EPS)

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
    columns[TARGET] = on_grid[TARGET]
    # setting and split keep the defaults (NaN, "unknown"): comma2k19 defines neither.
    return tidy_frame(
        columns,
        units={"speed": "m/s", "eps_torque": TORQUE_UNIT, TARGET: TORQUE_UNIT},
        attrs={"time_origin": {recording: float(start)}},
    )


def _sum(first, second):
    (times, a), (_, b) = first, second
    return times, a + b


def _read_signal(segment, parts):
    folder = "/".join(parts)
    times = segment.times(f"{folder}/t")
    values = segment.load(f"{folder}/value", "fiu", length_of=(f"{folder}/t", times), column=True)
    return times, values


def _derivative(values, sampling_rate, window):
    return savgol_filter(values, window, polyorder=2, deriv=1, delta=1.0 / sampling_rate)
