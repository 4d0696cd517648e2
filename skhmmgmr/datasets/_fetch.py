"""Fetcher of the comma2k19 driving dataset: its chunk archives, segments and cache layout.

The generic download, verification and unpacking helpers are in :mod:`._download`.
"""

import numbers
import re
import time
import warnings
import zipfile
from pathlib import Path

from ._base import get_data_home
from ._comma2k19 import ROUTE_PATTERN, check_sampling_rate, load_comma2k19_segment
from ._download import (
    atomic_open,
    check_zip,
    download,
    extract_folders,
    file_url,
    list_members,
    read_manifest,
    remove_stale_parts,
)
from ._frame import concat_frames

COMMA2K19_URL = "https://huggingface.co/datasets/commaai/comma2k19/resolve/main/"
N_CHUNKS = 10
_SEGMENT_ID = re.compile(
    r"^(?P<dongle>[0-9a-f]{16})(?:\||_|--)(?P<start>\d{4}-\d\d-\d\d--\d\d-\d\d-\d\d)"
    r"(?:/|--)(?P<number>\d+)/?$"
)


def _segment_key(identifier):
    match = _SEGMENT_ID.match(str(identifier))
    if match is None:
        raise ValueError(
            f"{identifier!r} is not a comma2k19 segment identifier such as "
            "'b0c9d2329ad1606b|2018-08-02--08-34-47/40' (or '...--40')."
        )
    return match["dongle"], match["start"], str(int(match["number"]))


def _key_of_member(parts):
    """Return (segment key, path inside the segment) of an archive member, or None."""
    for i in range(len(parts) - 2):
        match = ROUTE_PATTERN.match(parts[i])
        if match and parts[i + 1].isdigit():
            key = match["dongle"], match["start"], str(int(parts[i + 1]))
            return key, parts[i + 2 :]
    return None


def _segment_folder(root, key):
    dongle, start, number = key
    return root / f"{dongle}--{start}" / number


def _name(key):
    dongle, start, number = key
    return f"{dongle}|{start}--{number}"


def _check_chunks(chunks):
    chunks = [chunks] if isinstance(chunks, numbers.Integral) else list(chunks)
    for chunk in chunks:
        if not isinstance(chunk, numbers.Integral) or not 1 <= chunk <= N_CHUNKS:
            raise ValueError(f"chunks must be numbers from 1 to {N_CHUNKS}, got {chunk!r}.")
    if not chunks:
        raise ValueError("chunks must name at least one chunk.")
    return [int(c) for c in dict.fromkeys(chunks)]


class _Chunks:
    """Archives of comma2k19 chunks in the cache folder, downloaded on demand."""

    def __init__(self, root, base_url, checksums, download_if_missing, timeout):
        self.root = root
        self.base_url = base_url
        self.checksums = checksums
        self.download_if_missing = download_if_missing
        self.timeout = timeout

    def index_path(self, chunk):
        return self.root / f"Chunk_{chunk}.segments.txt"

    def read_index(self, chunk):
        path = self.index_path(chunk)
        if not path.is_file():
            return None
        return [_segment_key(line) for line in path.read_text().split() if line]

    def archive(self, chunk):
        name = f"Chunk_{chunk}.zip"
        path = self.root / name
        remove_stale_parts(path, time.time())
        if path.is_file():
            if zipfile.is_zipfile(path):
                return path
            problem = (
                f"The cached comma2k19 archive {str(path)!r} is not a readable zip archive "
                "(cut by an interrupted download of an earlier version?)"
            )
            if not self.download_if_missing:
                raise OSError(f"{problem}; delete it, or pass download_if_missing=True.")
            path.unlink()
            warnings.warn(f"{problem}; it was deleted and is downloaded again.", stacklevel=4)
        if not self.download_if_missing:
            raise OSError(
                f"The comma2k19 archive {name} is needed but not in the cache folder "
                f"{str(self.root)!r}, and download_if_missing=False."
            )
        if self.checksums is None:
            self.checksums = read_manifest(self.base_url, timeout=self.timeout) or {}
        expected = self.checksums.get(name)
        digest = download(
            file_url(self.base_url, name),
            path,
            sha256=expected,
            timeout=self.timeout,
            check=check_zip,
        )
        if expected is None:
            warnings.warn(
                f"No SHA-256 checksum is known for {name}: its download was checked as a zip "
                "archive (the CRC of every member), not against a published checksum (its "
                f"SHA-256 is {digest}; pass checksums={{{name!r}: ...}} to pin it).",
                UserWarning,
                stacklevel=4,
            )
        return path

    def unpack(self, chunk, wanted):
        """Unpack the segments in ``wanted`` (None: all) of a chunk; return its segment keys."""
        archive = self.archive(chunk)
        members = [m for m in map(_key_of_member, list_members(archive)) if m is not None]
        keys = list(dict.fromkeys(key for key, _ in members))
        self._write_index(chunk, keys)
        todo = {
            k
            for k in keys
            if (wanted is None or k in wanted) and not _segment_folder(self.root, k).is_dir()
        }
        if todo:

            def folder_of(parts):
                found = _key_of_member(parts)
                if found is None or found[0] not in todo or not found[1]:
                    return None
                return _segment_folder(Path(), found[0]), found[1]

            extract_folders(archive, self.root, folder_of)
        return keys

    def _write_index(self, chunk, keys):
        with atomic_open(self.index_path(chunk)) as f:
            f.write("".join(f"{_name(k)}\n" for k in keys))


def fetch_comma2k19(
    *,
    segments=None,
    chunks=1,
    data_home=None,
    download_if_missing=True,
    base_url=COMMA2K19_URL,
    checksums=None,
    keep_archive=True,
    sampling_rate=20.0,
    eps_torque=False,
    timeout=60.0,
):
    """Download (if needed) and load segments of the comma2k19 dataset.

    comma2k19 (comma.ai, MIT licence) is published as ten zip archives ``Chunk_1.zip`` to
    ``Chunk_10.zip`` of about 9 GB each; this function downloads a whole chunk into the cache
    folder, unpacks the requested segments into ``<data_home>/comma2k19/<route>/<segment>/``
    and loads each with :func:`load_comma2k19_segment`. Segments already unpacked are loaded
    without touching the network. Only chunks 1 and 2 (the Toyota RAV4) have the driver torque.

    Parameters
    ----------
    segments : str or list of str, default=None
        Segments to load, named ``"<dongle_id>|<route start>/<segment>"`` (``--`` may stand for
        ``|`` and for ``/``), for example ``"b0c9d2329ad1606b|2018-08-02--08-34-47/40"``.
        By default every segment of the chunks.
    chunks : int or list of int, default=1
        Chunks, from 1 to 10, to look for the segments in; downloaded in this order, and only
        until every requested segment is found.
    data_home : str or path-like, default=None
        Cache folder; see :func:`get_data_home`.
    download_if_missing : bool, default=True
        If False, raise an OSError instead of downloading what is not in the cache.
    base_url : str, default=COMMA2K19_URL
        Folder URL holding the ``Chunk_<n>.zip`` archives (``http``, ``https`` or ``file``).
        The default is comma.ai's copy on the Hugging Face Hub
        (``https://huggingface.co/datasets/commaai/comma2k19/resolve/main/``); the dataset is
        also shared on Academic Torrents, which needs a BitTorrent client: download a chunk
        there and pass ``base_url="file:///folder/of/the/chunks/"``.
    checksums : mapping of str to str, default=None
        Expected SHA-256 of archives, by file name (``{"Chunk_1.zip": "3f2a..."}``). By default
        they are read from a ``SHA256SUMS`` file (``sha256sum`` format) in ``base_url``; when
        there is none (as on the Hugging Face Hub), the download is not verified and a warning
        gives the SHA-256 of what was downloaded. A mismatch raises an OSError and keeps
        nothing.
    keep_archive : bool, default=True
        Whether to keep the archive in the cache to unpack other segments later without
        downloading it again.
    sampling_rate : float, default=20.0
        Rate of the time grid, in Hz; see :func:`load_comma2k19_segment`.
    eps_torque : bool, default=False
        Whether to add the power-steering motor torque; see :func:`load_comma2k19_segment`.
    timeout : float, default=60.0
        Seconds to wait for the server at each read.

    Returns
    -------
    frame : pandas.DataFrame
        The segments one after the other, in the order asked (by default the archive order),
        each a recording named ``route--segment``; columns as in
        :func:`load_comma2k19_segment`.

    Raises
    ------
    OSError
        Naming the URL and what failed, when a download fails (network, timeout, HTTP error,
        cut connection) or gives a damaged archive (wrong length or checksum, not a readable
        zip archive, a member failing its CRC check); nothing is kept.

    Notes
    -----
    Downloads go to a temporary file in the cache folder, renamed into place only once
    complete and verified (length, checksum when known, and always the zip archive's central
    directory and the CRC of every member); segments are unpacked into a temporary folder
    renamed into place, so an interruption never leaves a partial file where the cache expects
    a complete one. A temporary file that a killed download left is deleted at the next call;
    a cached archive that is not a readable zip archive is downloaded again. Archive members
    that would land outside the cache folder are refused.

    Examples
    --------
    >>> from skhmmgmr.datasets import fetch_comma2k19
    >>> df = fetch_comma2k19(segments="b0c9d2329ad1606b|2018-07-27--06-03-57/3")
    ... # doctest: +SKIP
    """
    check_sampling_rate(sampling_rate)
    chunk_numbers = _check_chunks(chunks)
    if checksums is not None:
        checksums = dict(checksums)
    root = Path(get_data_home(data_home)) / "comma2k19"
    root.mkdir(parents=True, exist_ok=True)
    store = _Chunks(root, base_url, checksums, download_if_missing, timeout)

    if segments is None:
        keys = []
        for chunk in chunk_numbers:
            index = store.read_index(chunk)
            if index is None or not all(_segment_folder(root, k).is_dir() for k in index):
                index = store.unpack(chunk, None)
                _drop_archive(store, chunk, keep_archive)
            keys.extend(index)
    else:
        identifiers = [segments] if isinstance(segments, str) else list(segments)
        keys = list(dict.fromkeys(_segment_key(s) for s in identifiers))
        for chunk in chunk_numbers:
            remaining = {k for k in keys if not _segment_folder(root, k).is_dir()}
            if not remaining:
                break
            index = store.read_index(chunk)
            if index is not None and not remaining & set(index):
                continue
            store.unpack(chunk, remaining)
            _drop_archive(store, chunk, keep_archive)
        remaining = [_name(k) for k in keys if not _segment_folder(root, k).is_dir()]
        if remaining:
            raise ValueError(
                f"Segment(s) {', '.join(remaining)} are in none of the comma2k19 chunk(s) "
                f"{', '.join(map(str, chunk_numbers))}."
            )

    parts = [
        load_comma2k19_segment(
            _segment_folder(root, k),
            sampling_rate=sampling_rate,
            recording=_name(k),
            eps_torque=eps_torque,
        )
        for k in keys
    ]
    if not parts:
        raise ValueError(f"The comma2k19 chunk(s) {chunk_numbers} hold no segment.")
    origins = {k: v for p in parts for k, v in p.attrs["time_origin"].items()}
    return concat_frames(parts, attrs={"time_origin": origins})


def _drop_archive(store, chunk, keep_archive):
    if not keep_archive:
        (store.root / f"Chunk_{chunk}.zip").unlink(missing_ok=True)
