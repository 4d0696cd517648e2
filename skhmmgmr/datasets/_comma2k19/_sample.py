"""The comma2k19 sample shipped with the package: one real minute, read without a download.

The sample is segment 40 of the route ``b0c9d2329ad1606b|2018-08-02--08-34-47`` of comma2k19
(comma.ai, MIT licence; ``data/comma2k19/LICENSE`` travels with it), reduced to the arrays the
loader reads, plus three signals that the package's tests compare the decoded ones with, and
packed as one compressed NumPy archive whose member names are the segment's file paths.
:func:`reduce_segment` and :func:`write_sample` rebuild it from a segment folder;
:func:`extract_sample` writes it back out as a segment folder.
"""

import io
import zipfile
from importlib import resources
from pathlib import Path

import numpy as np

from ..._core._compat import validate_params
from ._segment import (
    LOADER_CONSTRAINTS,
    SegmentFiles,
    check_options,
    segment_frame,
    with_loader_options,
)

SAMPLE_ROUTE = "b0c9d2329ad1606b|2018-08-02--08-34-47"
SAMPLE_SEGMENT = 40
SAMPLE_NAME = f"{SAMPLE_ROUTE}--{SAMPLE_SEGMENT}"
# The segment's folder name on disk: the route's "|" written "--" (portable).
SAMPLE_FOLDER = Path(SAMPLE_ROUTE.replace("|", "--"), str(SAMPLE_SEGMENT))
_ARCHIVE = ("data", "comma2k19", "b0c9d2329ad1606b--2018-08-02--08-34-47--40.npz")

_RAW_CAN = "processed_log/CAN/raw_can"
# (bus, CAN id) of the frames kept: those the loader decodes (STEER_TORQUE_SENSOR, KINEMATICS,
# STEER_ANGLE_SENSOR, EPS_STATUS, PCM_CRUISE, BRAKE_MODULE on the car's bus; openpilot's
# STEERING_LKA on the bus of the frames the device sent), and the wheel speeds (0xAA), which
# the tests decode to check the processed speed the loader reads.
KEPT_FRAMES = (
    (0, 0x260),
    (0, 0x24),
    (0, 0x25),
    (0, 0x262),
    (0, 0x1D2),
    (0, 0x224),
    (128, 0x2E4),
    (0, 0xAA),
)
# Files kept whole: the speed the loader reads; the processed steering angle and the phone gyro,
# independent measurements the tests compare the decoded angle and yaw rate with.
KEPT_FILES = (
    "processed_log/CAN/speed/t",
    "processed_log/CAN/speed/value",
    "processed_log/CAN/steering_angle/t",
    "processed_log/CAN/steering_angle/value",
    "processed_log/IMU/gyro/t",
    "processed_log/IMU/gyro/value",
)


class _ArchiveSegment(SegmentFiles):
    """The arrays of a segment packed in one ``.npz`` archive, member name = file path."""

    def __init__(self, path, archive):
        super().__init__(path)
        self.archive = archive

    def read(self, name):
        if name not in self.archive.files:
            raise FileNotFoundError(
                f"The comma2k19 archive {str(self.path)!r} has no member {name!r}."
            )
        return self.archive[name]


def sample_path():
    """The bundled archive as a file of the installed package (a traversable resource)."""
    return resources.files("skhmmgmr.datasets").joinpath(*_ARCHIVE)


def _open_sample():
    data = sample_path().read_bytes()
    return np.load(io.BytesIO(data), allow_pickle=False)


@validate_params(LOADER_CONSTRAINTS, prefer_skip_nested_validation=True)
@with_loader_options
def load_comma2k19_sample(
    *,
    sampling_rate=20.0,
    recording=None,
    eps_torque=False,
    engagement=False,
    steering="all",
    min_span=2.0,
):
    """Load the comma2k19 minute that ships with skhmmgmr, without a download.

    One real minute of public driving data: segment 40 of the comma2k19 route
    ``b0c9d2329ad1606b|2018-08-02--08-34-47``, a 2017 Toyota RAV4 on a California highway,
    with openpilot's lane keeping engaged for most of the minute. It is decoded exactly as
    :func:`load_comma2k19_segment` decodes a segment folder: the same columns, units, grid and
    options, and the same values as from the original segment. The sample keeps the CAN frames
    and files the loader reads (about 0.4 MB compressed); comma2k19 is by comma.ai under the
    MIT licence, whose text ships beside the sample
    (``skhmmgmr/datasets/data/comma2k19/LICENSE``).

    Parameters
    ----------
    {loader options}

    Returns
    -------
    frame : pandas.DataFrame
        The frame :func:`load_comma2k19_segment` returns for the segment: one row per grid
        time, the meta columns, the features, the optional columns asked for, and last the
        target ``driver_torque`` in **raw sensor units, not Nm**. The recording id is
        ``"b0c9d2329ad1606b|2018-08-02--08-34-47--40"`` unless ``recording`` is given.

    Raises
    ------
    ImportError
        When ``engagement`` or ``steering="driver"`` is asked without ``skhmmgmr[can]``.
    ValueError
        When an option is out of range.

    See Also
    --------
    load_comma2k19_segment : the same loader for any comma2k19 segment folder.
    fetch_comma2k19 : download segments of comma2k19.

    Examples
    --------
    >>> from skhmmgmr.datasets import load_comma2k19_sample
    >>> minute = load_comma2k19_sample()
    >>> minute.shape
    (1200, 13)
    >>> minute.attrs["units"]["driver_torque"]
    'raw sensor units'
    """
    sampling_rate, min_span = check_options(
        sampling_rate, engagement=engagement, steering=steering, min_span=min_span
    )
    recording = SAMPLE_NAME if recording is None else str(recording)
    with _open_sample() as archive:
        segment = _ArchiveSegment(Path(*_ARCHIVE), archive)
        return segment_frame(
            segment,
            recording,
            sampling_rate=sampling_rate,
            eps_torque=eps_torque,
            engagement=engagement,
            steering=steering,
            min_span=min_span,
        )


def reduce_segment(folder):
    """The arrays of the sample, read from a segment folder: file path -> array."""
    folder = Path(folder)
    raw = {name: np.load(folder / _RAW_CAN / name) for name in ("t", "address", "src", "data")}
    kept = np.zeros(len(raw["t"]), dtype=bool)
    for bus, address in KEPT_FRAMES:
        kept |= (raw["src"] == bus) & (raw["address"] == address)
    arrays = {f"{_RAW_CAN}/{name}": values[kept] for name, values in raw.items()}
    arrays.update({name: np.load(folder / name) for name in KEPT_FILES})
    return arrays


def write_sample(folder, path):
    """Write the sample archive of the segment ``folder`` to ``path`` (compressed ``.npz``)."""
    arrays = reduce_segment(folder)
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED, compresslevel=9) as zf:
        for name, array in arrays.items():
            buffer = io.BytesIO()
            np.save(buffer, array, allow_pickle=False)
            # a fixed date keeps the archive's bytes the same from one build to the next
            info = zipfile.ZipInfo(f"{name}.npy", date_time=(1980, 1, 1, 0, 0, 0))
            info.compress_type = zipfile.ZIP_DEFLATED
            zf.writestr(info, buffer.getvalue(), compresslevel=9)


def extract_sample(folder):
    """Write the sample out as a comma2k19 segment folder under ``folder`` (the route folder,
    then ``40``), each array a NumPy file without extension as in comma2k19; return the
    segment folder."""
    segment = Path(folder) / SAMPLE_FOLDER
    with _open_sample() as archive:
        for name in archive.files:
            file = segment / name
            file.parent.mkdir(parents=True, exist_ok=True)
            with open(file, "wb") as f:
                np.save(f, archive[name], allow_pickle=False)
    return segment
