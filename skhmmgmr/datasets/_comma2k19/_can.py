"""CAN decoding of comma2k19's Toyota RAV4: openpilot's DBC read by cantools, or a built-in table.

Two decoders give the same interface (``frame_id(message)``, ``decode(message, payloads)``):

- :class:`DbcDecoder` reads openpilot's DBC file of the 2017-18 RAV4,
  ``toyota_new_mc_pt_generated`` (the one ``opendbc.car.toyota.values`` gives the
  ``TOYOTA_RAV4`` platform), as the ``opendbc`` package generates it, with ``cantools``; it
  decodes every signal of every message. Both packages are the optional extra
  ``skhmmgmr[can]``; opendbc is MIT-licensed (Copyright (c) 2020, Comma.ai, Inc.).
- :class:`TableDecoder` is the fallback without them: the seven steering signals of
  :data:`TABLE`, written out by hand from the same DBC and decoded by
  :func:`decode_big_endian_signal`. The tests check that both decoders give equal values on a
  real segment.

Payloads are the ``|S8`` byte strings of comma2k19's ``raw_can/data``. NumPy drops trailing
zero bytes from them, so both decoders pad every payload back to 8 bytes with zeros; a DBC
message shorter than 8 bytes reads its first bytes only.
"""

import functools
from typing import NamedTuple

import numpy as np

# openpilot's DBC of the 2017-18 RAV4 (opendbc.car.toyota.values: TOYOTA_RAV4).
DBC_NAME = "toyota_new_mc_pt_generated"
INSTALL_HINT = (
    "install them with pip install 'skhmmgmr[can]' (opendbc supports Python 3.11 and 3.12)"
)


class CANSignal(NamedTuple):
    """A signal of a CAN message, as a DBC file defines it (big-endian bit order)."""

    address: int
    start_bit: int
    length: int
    signed: bool
    scale: float
    offset: float


# (message, signal) -> definition, copied from the DBC. STEER_FRACTION, the 0.1 deg complement of
# STEER_ANGLE, is needed: the processed CAN/steering_angle of comma2k19 is exactly their sum.
TABLE = {
    ("STEER_TORQUE_SENSOR", "STEER_TORQUE_DRIVER"): CANSignal(0x260, 15, 16, True, 1.0, 0.0),
    ("STEER_TORQUE_SENSOR", "STEER_TORQUE_EPS"): CANSignal(0x260, 47, 16, True, 1.0, 0.0),
    ("KINEMATICS", "YAW_RATE"): CANSignal(0x24, 1, 10, False, 0.244, -125.0),
    ("KINEMATICS", "ACCEL_Y"): CANSignal(0x24, 33, 10, False, 0.03589, -18.375),
    ("STEER_ANGLE_SENSOR", "STEER_ANGLE"): CANSignal(0x25, 3, 12, True, 1.5, 0.0),
    ("STEER_ANGLE_SENSOR", "STEER_FRACTION"): CANSignal(0x25, 39, 4, True, 0.1, 0.0),
    ("STEER_ANGLE_SENSOR", "STEER_RATE"): CANSignal(0x25, 35, 12, True, 1.0, 0.0),
}


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


class TableDecoder:
    """Decodes the signals of :data:`TABLE`, without any package beyond NumPy."""

    source = "the built-in table of seven steering signals"

    def frame_id(self, message):
        """The CAN id of ``message``."""
        for (name, _), signal in TABLE.items():
            if name == message:
                return signal.address
        raise ImportError(
            f"The CAN message {message} is decoded with openpilot's DBC file, read by cantools: "
            f"{INSTALL_HINT}."
        )

    def decode(self, message, data):
        """The table's signals of ``message`` in the payloads ``data``, as float arrays."""
        return {
            name: decode_big_endian_signal(
                data, s.start_bit, s.length, signed=s.signed, scale=s.scale, offset=s.offset
            )
            for (owner, name), s in TABLE.items()
            if owner == message
        }


class DbcDecoder:
    """Decodes every signal of a cantools database, once per distinct payload."""

    def __init__(self, database, source):
        self.database = database
        self.source = source

    def frame_id(self, message):
        """The CAN id of ``message``."""
        return self.database.get_message_by_name(message).frame_id

    def decode(self, message, data):
        """Every signal of ``message`` in the payloads ``data``, as float arrays (raw values of
        enumerations: ``decode_choices=False``)."""
        definition = self.database.get_message_by_name(message)
        payloads, inverse = np.unique(np.asarray(data, dtype="S8"), return_inverse=True)
        rows = [
            definition.decode(bytes(p).ljust(8, b"\0")[: definition.length], decode_choices=False)
            for p in payloads
        ]
        return {
            s.name: np.array([row[s.name] for row in rows], dtype=float).reshape(-1)[
                inverse.reshape(-1)
            ]
            for s in definition.signals
        }

    def choice(self, message, signal, name):
        """The raw value the DBC names ``name`` in the value table of ``message.signal``."""
        choices = self.database.get_message_by_name(message).get_signal_by_name(signal).choices
        found = [raw for raw, text in (choices or {}).items() if str(text) == name]
        if not found:
            raise ValueError(f"The DBC {self.source} names no value {name!r} of {signal}.")
        return int(found[0])


@functools.cache
def dbc_decoder():
    """The decoder of openpilot's RAV4 DBC; ImportError when ``skhmmgmr[can]`` is missing."""
    try:
        import cantools
        from opendbc import get_generated_dbcs
    except ImportError as exc:
        raise ImportError(
            f"{exc.name or exc} is not installed. The engagement signals of comma2k19 are "
            f"decoded with openpilot's DBC file, read by cantools: {INSTALL_HINT}."
        ) from exc
    texts = get_generated_dbcs()
    if DBC_NAME not in texts:
        raise ImportError(f"The installed opendbc generates no DBC named {DBC_NAME}.")
    # Not strict: the DBC has overlapping signals in a message the loader does not read
    # (PCS_HUD), which openpilot's own parser accepts.
    database = cantools.database.load_string(texts[DBC_NAME], database_format="dbc", strict=False)
    return DbcDecoder(database, f"{DBC_NAME} of opendbc")


def can_decoder(*, need_dbc=False):
    """openpilot's DBC when ``skhmmgmr[can]`` is installed, else the table (or ImportError if
    ``need_dbc``)."""
    try:
        return dbc_decoder()
    except ImportError:
        if need_dbc:
            raise
        return TableDecoder()
