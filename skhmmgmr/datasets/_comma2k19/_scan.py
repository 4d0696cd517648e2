"""Who steers in each comma2k19 segment, read from the CAN logs alone, by byte ranges.

For each segment of the chunks asked, only ``processed_log/CAN/raw_can/*`` and
``processed_log/CAN/speed/*`` (about 4.4 MB of the segment's 50) are read out of the remote
archive (:func:`._fetch.unpack_segments`, 8 segments' members fetched at once) into a temporary
folder, loaded with :func:`load_comma2k19_segment` and its engagement columns (openpilot's DBC,
``skhmmgmr[can]``), summed up in one row, and deleted.
"""

import shutil
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd

from ..._core._compat import validate_params
from .._download import file_url
from .._remote import check_url, remote_zip, require
from ._fetch import (
    COMMA2K19_URL,
    REMOTE_CONSTRAINTS,
    check_chunks,
    segment_folder,
    segment_members,
    segment_name,
    unpack_segments,
)
from ._segment import FRAME_CONSTRAINTS, check_options, load_comma2k19_segment

# The CAN folders the loader reads: raw frames (steering, engagement) and the wheel speed.
SCAN_FOLDERS = (("processed_log", "CAN", "raw_can"), ("processed_log", "CAN", "speed"))
# openpilot's "steering pressed": more than 100 raw units of driver torque.
PRESSED = 100.0
COLUMNS = {
    "segment": "segment identifier, as fetch_comma2k19 takes it",
    "chunk": "chunk number",
    "duration_s": "length of the time grid, s",
    "manual_s": "time the driver steers alone (no openpilot request, lane keeping inactive), s",
    "longest_manual_s": "longest span the driver steers alone, s",
    "engaged_s": "time the cruise control (so openpilot) is engaged, s",
    "pressed_s": "time the driver torque exceeds 100 raw units, s",
    "speed_min": "lowest speed, m/s",
    "speed_max": "highest speed, m/s",
    "problem": "why the segment could not be read (empty when it could)",
}


@validate_params(
    REMOTE_CONSTRAINTS | {"sampling_rate": FRAME_CONSTRAINTS["sampling_rate"]},
    prefer_skip_nested_validation=True,
)
def scan_comma2k19(
    chunks=(1, 2), *, base_url=COMMA2K19_URL, sampling_rate=20.0, timeout=60.0, progress=True
):
    """Tell, for each segment of comma2k19 chunks, how long the driver steers alone.

    Reads only the CAN logs of each segment out of the remote archives, by byte ranges (about
    4.4 MB a segment and the archive's central directory, instead of 9 GB a chunk), decodes
    who steers with openpilot's DBC (the engagement columns of
    :func:`load_comma2k19_segment`) and keeps nothing on disk. The table it returns picks the
    segments worth fetching: ``fetch_comma2k19(segments=scan.loc[scan.manual_s > 30,
    "segment"])``.

    Parameters
    ----------
    chunks : int or list of int, default=(1, 2)
        Chunks to scan, from 1 to 10. Only chunks 1 and 2 (the Toyota RAV4) can be decoded; the
        segments of other chunks get a ``problem``.
    base_url : str, default=COMMA2K19_URL
        Folder URL holding the ``Chunk_<n>.zip`` archives (``http``, ``https``, ``file`` or
        ``hf``); see :func:`fetch_comma2k19`. The server must honour Range requests.
    sampling_rate : float, default=20.0
        Rate of the time grid the durations are counted on, in Hz.
    timeout : float, default=60.0
        Seconds to wait for the server at each read.
    progress : bool, default=True
        Whether to show a progress bar of the segments (tqdm).

    Returns
    -------
    scan : pandas.DataFrame
        One row per segment, in archive order, with the columns

        - ``segment``: identifier ``"<dongle>|<route start>--<number>"``;
        - ``chunk``: chunk number;
        - ``duration_s``: seconds covered by the time grid;
        - ``manual_s``: seconds the driver steers alone: openpilot requests no steering torque
          and the power steering's lane keeping is inactive (``openpilot_steer_request`` and
          ``eps_lka_active`` both 0, as ``steering="driver"`` keeps);
        - ``longest_manual_s``: the longest such span, in seconds;
        - ``engaged_s``: seconds with the adaptive cruise control, so openpilot, engaged
          (``cruise_active``);
        - ``pressed_s``: seconds with more than 100 raw units of driver torque (openpilot's
          "steering pressed"), engaged or not;
        - ``speed_min``, ``speed_max``: speed range, m/s;
        - ``problem``: empty, or why the segment could not be decoded (its numbers are NaN).

    Raises
    ------
    ImportError
        Before any network access, without ``skhmmgmr[can]`` (openpilot's DBC) or
        ``skhmmgmr[fetch]`` (fsspec, aiohttp, huggingface_hub).
    OSError
        Naming the URL and what failed: network, timeout, HTTP error, a server ignoring Range
        requests, a member failing its CRC check.

    Notes
    -----
    The time taken is mostly the requests: each segment costs one or two Range requests
    (4.4 MB), 8 segments at a time concurrently, and the decoding about 0.3 s. See the user
    guide (:doc:`/user_guide/comma2k19`) for measured times.

    Examples
    --------
    >>> from skhmmgmr.datasets import fetch_comma2k19, scan_comma2k19
    >>> scan = scan_comma2k19(chunks=1)  # doctest: +SKIP
    >>> df = fetch_comma2k19(segments=scan.loc[scan.manual_s > 30, "segment"])  # doctest: +SKIP
    """
    sampling_rate, _ = check_options(sampling_rate, engagement=True)
    chunk_numbers = check_chunks(chunks)
    check_url(file_url(base_url, "Chunk_1.zip"))
    require("fsspec")
    rows = []
    for chunk in chunk_numbers:
        url = file_url(base_url, f"Chunk_{chunk}.zip")
        with remote_zip(url, timeout=timeout) as (archive, reader):
            members = {
                key: [m for m in found if tuple(m[2][:3]) in SCAN_FOLDERS]
                for key, found in segment_members(archive).items()
            }
            with tempfile.TemporaryDirectory(prefix="skhmmgmr-scan-") as tmp:
                batches = unpack_segments(
                    archive, reader, tmp, members, progress=progress, desc=f"Chunk_{chunk}"
                )
                for batch in batches:
                    rows.extend(_summary(Path(tmp), key, chunk, sampling_rate) for key in batch)
    return pd.DataFrame(rows, columns=list(COLUMNS))


def _summary(root, key, chunk, sampling_rate):
    """The scan's row of the segment ``key`` unpacked in ``root``; its folder is deleted."""
    folder = segment_folder(root, key)
    row = {"segment": segment_name(key), "chunk": chunk, "problem": ""}
    try:
        frame = load_comma2k19_segment(
            folder, sampling_rate=sampling_rate, recording=row["segment"], engagement=True
        )
    except (ValueError, FileNotFoundError) as exc:
        return {**row, **dict.fromkeys(list(COLUMNS)[2:-1], np.nan), "problem": str(exc)}
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    alone = (frame["openpilot_steer_request"] == 0) & (frame["eps_lka_active"] == 0)
    edges = np.flatnonzero(np.diff(np.concatenate(([0], alone.to_numpy(np.int8), [0]))))
    longest = int((edges[1::2] - edges[::2]).max()) if edges.size else 0
    return {
        **row,
        "duration_s": len(frame) / sampling_rate,
        "manual_s": int(alone.sum()) / sampling_rate,
        "longest_manual_s": longest / sampling_rate,
        "engaged_s": int((frame["cruise_active"] == 1).sum()) / sampling_rate,
        "pressed_s": int((frame["driver_torque"].abs() > PRESSED).sum()) / sampling_rate,
        "speed_min": float(frame["speed"].min()),
        "speed_max": float(frame["speed"].max()),
    }
