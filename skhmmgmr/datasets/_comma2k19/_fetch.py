"""Fetcher of the comma2k19 driving dataset: its chunk archives, segments and cache layout.

comma2k19 is ten zip archives ``Chunk_<n>.zip`` of about 9 GB, each holding segments
``Chunk_<n>/<dongle>|<route start>/<number>/``. By default the segments asked for are read out
of the remote archive by byte ranges (:mod:`.._remote`): its central directory, then the members
of the segment's ``processed_log/`` and ``global_pose/`` folders (a few MB), never its video;
``method="archive"`` downloads the whole archive, resumably, and keeps it. The generic
verification and unpacking helpers are in :mod:`.._download`.
"""

import numbers
import re
import reprlib
import shutil
import time
import warnings
import zipfile
from collections.abc import Iterable, Mapping
from contextlib import contextmanager
from numbers import Integral, Real
from pathlib import Path

from tqdm.auto import tqdm

from ..._core._compat import FiniteInterval, Interval, StrOptions, validate_params
from .._base import DATA_HOME, get_data_home
from .._download import (
    atomic_open,
    check_zip,
    extract_folders,
    file_url,
    member_parts,
    remove_stale_parts,
)
from .._frame import concat_frames
from .._remote import (
    check_url,
    download,
    hub_sha256,
    member_ranges,
    read_manifest,
    remote_zip,
)
from ._segment import (
    FRAME_CONSTRAINTS,
    ROUTE_PATTERN,
    DamagedSegmentError,
    check_options,
    load_comma2k19_segment,
)

COMMA2K19_URL = "https://huggingface.co/datasets/commaai/comma2k19/resolve/main/"
N_CHUNKS = 10
METHODS = ("range", "archive")
#: What the fetcher and the scan take of a remote source: the chunks (their numbers checked
#: by :func:`check_chunks`), the folder URL, the timeout of a read, the progress bars.
REMOTE_CONSTRAINTS = {
    "chunks": [Interval(Integral, 1, N_CHUNKS, closed="both"), "array-like"],
    "base_url": [str],
    "timeout": [FiniteInterval(Real, 0, None, closed="neither")],
    "progress": ["boolean"],
}
# Folders of a segment that range reads fetch: the loader's inputs, not the video.
RANGE_FOLDERS = ("processed_log", "global_pose")
# Segments whose members are fetched at once (concurrent requests).
_BATCH = 8
# What a member of a segment may hold unpacked: a minute of video is about 50 MB, every other
# file a minute of one signal (the CAN log's arrays, the largest, about 1 MB each).
_VIDEO_SIZE = 256 << 20
_FILE_SIZE = 64 << 20


def member_cap(parts):
    """The most bytes the segment member with path parts ``parts`` may unpack to."""
    return _VIDEO_SIZE if parts[-1].endswith(".hevc") else _FILE_SIZE


# Segment numbers: a route's minutes, 0 to a few hundred; longer runs of digits are no segment.
_MAX_DIGITS = 6
_SEGMENT_ID = re.compile(
    r"^(?P<dongle>[0-9a-f]{16})(?:\||_|--)(?P<start>\d{4}-\d\d-\d\d--\d\d-\d\d-\d\d)"
    rf"(?:/|--)(?P<number>\d{{1,{_MAX_DIGITS}}})/?$"
)


def segment_key(identifier):
    """(dongle, route start, number) of a segment identifier; ValueError naming a bad one."""
    match = _SEGMENT_ID.match(str(identifier))
    if match is None:
        raise ValueError(
            f"{reprlib.repr(identifier)} is not a comma2k19 segment identifier such as "
            "'b0c9d2329ad1606b|2018-08-02--08-34-47/40' (or '...--40')."
        )
    return match["dongle"], match["start"], str(int(match["number"]))


def _key_of_member(parts):
    """Return (segment key, path inside the segment) of an archive member, or None."""
    for i in range(len(parts) - 2):
        match = ROUTE_PATTERN.match(parts[i])
        if match and parts[i + 1].isdigit() and len(parts[i + 1]) <= _MAX_DIGITS:
            key = match["dongle"], match["start"], str(int(parts[i + 1]))
            return key, parts[i + 2 :]
    return None


def segment_folder(root, key):
    """The cache folder ``<root>/<dongle>--<route start>/<number>`` of a segment."""
    dongle, start, number = key
    return Path(root) / f"{dongle}--{start}" / number


def segment_name(key):
    """The recording name ``<dongle>|<route start>--<number>`` of a segment."""
    dongle, start, number = key
    return f"{dongle}|{start}--{number}"


def check_chunks(chunks):
    """The chunk numbers asked for, as a list without repeats; ValueError outside 1 to 10."""
    chunks = [chunks] if isinstance(chunks, numbers.Integral) else list(chunks)
    for chunk in chunks:
        if not isinstance(chunk, numbers.Integral) or not 1 <= chunk <= N_CHUNKS:
            raise ValueError(f"chunks must be numbers from 1 to {N_CHUNKS}, got {chunk!r}.")
    if not chunks:
        raise ValueError("chunks must name at least one chunk.")
    return [int(c) for c in dict.fromkeys(chunks)]


def segment_members(archive):
    """Segment key -> [(ZipInfo, member path parts, path parts inside the segment)] of the
    regular files of a chunk archive, in archive order."""
    members = {}
    for info in archive.infolist():
        if info.is_dir():
            continue
        parts = member_parts(info.filename, Path(str(archive.filename)).name)
        found = _key_of_member(parts)
        if found is not None and found[1]:
            members.setdefault(found[0], []).append((info, parts, found[1]))
    return members


def unpack_segments(archive, reader, root, members, *, progress=False, desc=None):
    """Unpack the members ``{key: [(info, parts, inside), ...]}`` into ``<root>/<route>/<number>/``.

    A batch of segments at a time: their byte ranges are fetched at once when ``reader`` (the
    archive's :class:`.._remote.RangeReader`) is given, their folders are renamed into place
    whole (:func:`.._download.extract_folders`), then the batch's keys are yielded.
    """
    keys = list(members)
    with tqdm(total=len(keys), unit="segment", desc=desc, disable=not progress) as bar:
        for i in range(0, len(keys), _BATCH):
            batch = keys[i : i + _BATCH]
            where = {
                parts: (segment_folder(Path(), key), inside)
                for key in batch
                for _, parts, inside in members[key]
            }
            if reader is not None:
                infos = [info for key in batch for info, _, _ in members[key]]
                reader.prefetch(member_ranges(archive, infos))
            try:
                extract_folders(archive, root, where.get, max_size=member_cap)
            finally:
                if reader is not None:
                    reader.clear()
            bar.update(len(batch))
            yield batch


class _Chunks:
    """Archives of comma2k19 chunks: in the cache folder, downloaded, or read by byte ranges."""

    def __init__(self, root, base_url, options):
        self.root = root
        self.base_url = base_url
        self.options = options
        self.checksums = options["checksums"]

    def index_path(self, chunk):
        return self.root / f"Chunk_{chunk}.segments.txt"

    def read_index(self, chunk):
        path = self.index_path(chunk)
        if not path.is_file():
            return None
        return [segment_key(line) for line in path.read_text().split() if line]

    def cached(self, chunk):
        """The cached archive of ``chunk`` if it is a readable zip archive, else None."""
        path = self.root / f"Chunk_{chunk}.zip"
        remove_stale_parts(path, time.time())
        if not path.is_file() or zipfile.is_zipfile(path):
            return path if path.is_file() else None
        problem = (
            f"The cached comma2k19 archive {str(path)!r} is not a readable zip archive "
            "(cut by an interrupted download of an earlier version?)"
        )
        if not self.options["download_if_missing"]:
            raise OSError(f"{problem}; delete it, or pass download_if_missing=True.")
        path.unlink()
        warnings.warn(f"{problem}; it was deleted and is downloaded again.", stacklevel=5)
        return None

    def download(self, chunk):
        name = f"Chunk_{chunk}.zip"
        url = file_url(self.base_url, name)
        expected = None if self.checksums is None else self.checksums.get(name)
        if self.checksums is None:
            expected = hub_sha256(url)
            if expected is None and not url.startswith("hf://"):
                manifest = read_manifest(self.base_url, timeout=self.options["timeout"])
                expected = (manifest or {}).get(name)
        digest = download(
            url,
            self.root / name,
            sha256=expected,
            timeout=self.options["timeout"],
            check=check_zip,
            progress=self.options["progress"],
        )
        if expected is None:
            warnings.warn(
                f"No SHA-256 checksum is known for {name}: its download was checked as a zip "
                "archive (the CRC of every member), not against a published checksum (its "
                f"SHA-256 is {digest}; pass checksums={{{name!r}: ...}} to pin it).",
                UserWarning,
                stacklevel=5,
            )
        return self.root / name

    @contextmanager
    def open(self, chunk):
        """Yield the chunk's archive (a ZipFile) and its RangeReader (None when local)."""
        path = self.cached(chunk)
        if path is None and not self.options["download_if_missing"]:
            raise OSError(
                f"The comma2k19 archive Chunk_{chunk}.zip is needed but not in the cache folder "
                f"{str(self.root)!r}, and download_if_missing=False."
            )
        if path is None and self.options["method"] == "archive":
            path = self.download(chunk)
        if path is not None:
            with zipfile.ZipFile(path) as archive:
                yield archive, None
            return
        url = file_url(self.base_url, f"Chunk_{chunk}.zip")
        with remote_zip(url, timeout=self.options["timeout"]) as (archive, reader):
            yield archive, reader

    def unpack(self, chunk, wanted):
        """Unpack the segments in ``wanted`` (None: all) of a chunk; return its segment keys."""
        with self.open(chunk) as (archive, reader):
            members = segment_members(archive)
            keys = list(members)
            todo = {}
            for key in keys:
                if (wanted is None or key in wanted) and not segment_folder(
                    self.root, key
                ).is_dir():
                    todo[key] = [
                        m for m in members[key] if reader is None or m[2][0] in RANGE_FOLDERS
                    ]
            desc = f"Chunk_{chunk}"
            progress = self.options["progress"] and reader is not None
            for _ in unpack_segments(
                archive, reader, self.root, todo, progress=progress, desc=desc
            ):
                pass
        self._write_index(chunk, keys)
        if not self.options["keep_archive"]:
            (self.root / f"Chunk_{chunk}.zip").unlink(missing_ok=True)
        return keys

    def _write_index(self, chunk, keys):
        with atomic_open(self.index_path(chunk)) as f:
            f.write("".join(f"{segment_name(k)}\n" for k in keys))


@validate_params(
    {
        "segments": [str, Iterable, None],
        "data_home": DATA_HOME,
        "download_if_missing": ["boolean"],
        "method": [StrOptions(set(METHODS))],
        "checksums": [Mapping, None],
        "keep_archive": ["boolean"],
    }
    | REMOTE_CONSTRAINTS
    | FRAME_CONSTRAINTS,
    prefer_skip_nested_validation=True,
)
def fetch_comma2k19(
    *,
    segments=None,
    chunks=1,
    data_home=None,
    download_if_missing=True,
    base_url=COMMA2K19_URL,
    method="range",
    checksums=None,
    keep_archive=True,
    sampling_rate=20.0,
    eps_torque=False,
    engagement=False,
    steering="all",
    min_span=2.0,
    timeout=60.0,
    progress=True,
):
    """Fetch (if needed) and load segments of the comma2k19 dataset.

    comma2k19 (comma.ai, MIT licence) is published as ten zip archives ``Chunk_1.zip`` to
    ``Chunk_10.zip`` of about 9 GB each. By default (``method="range"``) this function reads
    the requested segments straight out of the remote archive with HTTP Range requests: the
    archive's central directory (1 to 2 MB for a real chunk), then the files of each segment's
    ``processed_log/`` and ``global_pose/`` folders (a few MB; not its video), unpacked into
    ``<data_home>/comma2k19/<route>/<segment>/``. Each segment is then loaded with
    :func:`load_comma2k19_segment`. Segments already unpacked are loaded without touching the
    network. Only chunks 1 and 2 (the Toyota RAV4) have the driver torque;
    :func:`scan_comma2k19` tells which of their segments the driver steers.

    Parameters
    ----------
    segments : str or list of str, default=None
        Segments to load, named ``"<dongle_id>|<route start>/<segment>"`` (``--`` may stand for
        ``|`` and for ``/``), for example ``"b0c9d2329ad1606b|2018-08-02--08-34-47/40"``; any
        iterable of them, such as a column of :func:`scan_comma2k19`'s table
        (``scan.loc[scan.manual_s > 30, "segment"]``). By default every segment of the chunks.
    chunks : int or list of int, default=1
        Chunks, from 1 to 10, to look for the segments in; read in this order, and only until
        every requested segment is found.
    data_home : str or path-like, default=None
        Cache folder; see :func:`get_data_home`.
    download_if_missing : bool, default=True
        If False, raise an OSError instead of reading what is not in the cache.
    base_url : str, default=COMMA2K19_URL
        Folder URL holding the ``Chunk_<n>.zip`` archives: ``http``, ``https``, ``file``, or
        ``hf://datasets/<owner>/<name>/`` (the Hugging Face Hub's file system). The default is
        comma.ai's copy on the Hugging Face Hub
        (``https://huggingface.co/datasets/commaai/comma2k19/resolve/main/``); the dataset is
        also shared on Academic Torrents, which needs a BitTorrent client: download a chunk
        there and pass ``base_url="file:///folder/of/the/chunks/"``.
    method : {"range", "archive"}, default="range"
        ``"range"`` reads only the central directory and the segments' members by byte ranges
        (the server must honour Range requests, as the Hub does). ``"archive"`` downloads the
        whole chunk into the cache folder first (resuming an interrupted download of it, with a
        progress bar), verified against its SHA-256, then unpacks every file of the segments
        from it. A chunk archive already in the cache is read locally with either method.
    checksums : mapping of str to str, default=None
        With ``method="archive"``: expected SHA-256 of archives, by file name
        (``{"Chunk_1.zip": "3f2a..."}``). By default the SHA-256 the Hugging Face Hub publishes
        for the file when ``base_url`` is a Hub dataset (its API's ``lfs.sha256``, read with
        ``huggingface_hub``), else the one in a ``SHA256SUMS`` file (``sha256sum`` format) in
        ``base_url``; when there is none, the download is only checked as a zip archive and a
        warning gives its SHA-256. A mismatch raises an OSError and keeps nothing. Range reads
        check each member against the CRC-32 of the central directory instead.
    keep_archive : bool, default=True
        With ``method="archive"``: whether to keep the archive in the cache to unpack other
        segments later without downloading it again.
    sampling_rate : float, default=20.0
        Rate of the time grid, in Hz; see :func:`load_comma2k19_segment`.
    eps_torque : bool, default=False
        Whether to add the power-steering motor torque; see :func:`load_comma2k19_segment`.
    engagement : bool, default=False
        Whether to add the columns that tell who steers (needs ``skhmmgmr[can]``); see
        :func:`load_comma2k19_segment`.
    steering : {"all", "driver"}, default="all"
        ``"driver"`` keeps the spans the driver steers alone, each a recording
        ``"route--segment/span<k>"`` (needs ``skhmmgmr[can]``); see
        :func:`load_comma2k19_segment`.
    min_span : float, default=2.0
        Shortest span kept with ``steering="driver"``, in seconds.
    timeout : float, default=60.0
        Seconds to wait for the server at each read.
    progress : bool, default=True
        Whether to show progress bars (tqdm): bytes of an archive download, segments of range
        reads.

    Returns
    -------
    frame : pandas.DataFrame
        The segments one after the other, in the order asked (by default the archive order),
        each a recording named ``route--segment`` (or its spans); columns as in
        :func:`load_comma2k19_segment`.

    Raises
    ------
    ImportError
        Before any download, when ``engagement`` or ``steering="driver"`` is asked without
        ``skhmmgmr[can]``; when the network is needed without ``skhmmgmr[fetch]`` (fsspec,
        aiohttp, huggingface_hub).
    OSError
        Naming the URL and what failed, when a read fails (network, timeout, HTTP error, cut
        connection, a server ignoring Range requests) or gives damaged data (a member failing
        its CRC check, named; with ``method="archive"``: wrong length or checksum, not a
        readable zip archive); nothing damaged is kept.

    Notes
    -----
    Segments are unpacked into a temporary folder renamed into place once all their files are
    read and verified, so an interruption never leaves a partial folder where the cache
    expects a complete one. With ``method="archive"`` the download goes to a hidden
    ``.Chunk_<n>.zip.part`` file in the cache folder: an interrupted download (cut connection,
    timeout, Ctrl-C) keeps it and the next call resumes it with a Range request; it is renamed
    into place only once complete and verified (checksum when known, and always the zip
    archive's central directory and the CRC of every member); a failed check deletes it. A
    cached archive that is not a readable zip archive is downloaded again. Archive members that
    would land outside the cache folder are refused, and so is an archive with a member that
    would unpack to more than such a file may hold (256 MB for a video, 64 MB for any other
    file; a compressed member to more than 100 times its compressed size), naming the member;
    nothing of it is kept. A cached segment whose files the loader refuses as damaged is
    removed from the cache (the error says so), so that the next call fetches it again.

    With range reads each segment costs its members (about 5 MB for a whole segment's logs)
    plus a few requests; the members of 8 segments at a time are fetched concurrently, in
    requests of at most 4 MB, at most 16 MB of them held in memory at once (the rest waits in
    a temporary file). See the user guide (:doc:`/user_guide/comma2k19`) for measured times.

    Examples
    --------
    >>> from skhmmgmr.datasets import fetch_comma2k19
    >>> df = fetch_comma2k19(segments="b0c9d2329ad1606b|2018-07-27--06-03-57/3")
    ... # doctest: +SKIP
    """
    check_options(sampling_rate, engagement=engagement, steering=steering, min_span=min_span)
    chunk_numbers = check_chunks(chunks)
    check_url(file_url(base_url, "Chunk_1.zip"))
    options = {
        "checksums": None if checksums is None else dict(checksums),
        "download_if_missing": download_if_missing,
        "keep_archive": keep_archive,
        "method": method,
        "timeout": timeout,
        "progress": progress,
    }
    root = Path(get_data_home(data_home)) / "comma2k19"
    root.mkdir(parents=True, exist_ok=True)
    store = _Chunks(root, base_url, options)

    if segments is None:
        keys = []
        for chunk in chunk_numbers:
            index = store.read_index(chunk)
            if index is None or not all(segment_folder(root, k).is_dir() for k in index):
                index = store.unpack(chunk, None)
            keys.extend(index)
    else:
        identifiers = [segments] if isinstance(segments, str) else list(segments)
        keys = list(dict.fromkeys(segment_key(s) for s in identifiers))
        for chunk in chunk_numbers:
            remaining = {k for k in keys if not segment_folder(root, k).is_dir()}
            if not remaining:
                break
            index = store.read_index(chunk)
            if index is not None and not remaining & set(index):
                continue
            store.unpack(chunk, remaining)
        remaining = [segment_name(k) for k in keys if not segment_folder(root, k).is_dir()]
        if remaining:
            raise ValueError(
                f"Segment(s) {', '.join(remaining)} are in none of the comma2k19 chunk(s) "
                f"{', '.join(map(str, chunk_numbers))}."
            )

    loader_options = {
        "sampling_rate": sampling_rate,
        "eps_torque": eps_torque,
        "engagement": engagement,
        "steering": steering,
        "min_span": min_span,
    }
    parts = [_load_cached(root, k, loader_options) for k in keys]
    if not parts:
        raise ValueError(f"The comma2k19 chunk(s) {chunk_numbers} hold no segment.")
    origins = {k: v for p in parts for k, v in p.attrs["time_origin"].items()}
    return concat_frames(parts, attrs={"time_origin": origins})


def _load_cached(root, key, loader_options):
    """Load a segment of the cache; a segment the loader refuses as damaged (a file missing,
    unreadable, of the wrong type or length) is removed from the cache, so that the next call
    fetches it again instead of failing on the same files."""
    folder = segment_folder(root, key)
    try:
        return load_comma2k19_segment(folder, recording=segment_name(key), **loader_options)
    except (DamagedSegmentError, FileNotFoundError) as exc:
        shutil.rmtree(folder, ignore_errors=True)
        raise type(exc)(
            f"{exc} The segment's folder was removed from the cache: the next call fetches it "
            "again."
        ) from exc
