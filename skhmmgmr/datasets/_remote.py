"""Remote files through fsspec: zip archives read by byte ranges, resumable downloads, checksums.

Needs the optional extra ``skhmmgmr[fetch]``: fsspec opens ``file``, ``http(s)`` (with aiohttp)
and ``hf://`` URLs (the Hugging Face Hub's own file system, from huggingface_hub) as seekable
files; huggingface_hub also gives the SHA-256 the Hub publishes for a file.

Range reads (:func:`remote_zip`). :class:`zipfile.ZipFile` reads an archive through a
:class:`RangeReader`: a seekable file whose reads become HTTP Range requests. Opening it reads
the end of the archive and its central directory (a few requests, about 150 bytes per member).
The byte ranges of the members wanted, each from its local header to the next member's (so
the local header, its extra field and any data descriptor are inside), are then fetched at once
with fsspec's ``cat_ranges`` (concurrent requests over HTTP; ranges less than 64 KiB apart
merged into one, and cut into requests of at most 4 MiB) and written to a temporary file as
they come, at most 16 MiB held in memory at once whatever the members' size, so that reading
the members costs no further request (fsspec's own "parts" cache is filled only when a file is
opened, holds the parts in memory, and its answer to a read outside the parts differs between
fsspec versions, hence the reader keeps them itself). Every member read is checked against the
CRC-32 of the central directory by zipfile itself.

Downloads (:func:`download`) go to a hidden ``.<name>.part`` file beside the target, in blocks
of 16 MiB, each one Range request; an interrupted download (cut connection, timeout, Ctrl-C)
keeps it, and the next download of the same file resumes it from its end. The whole file's
SHA-256 is computed on the way (the kept part is read once more on resumption), checked against
the one expected, then the file is checked by the caller (such as the CRC of every zip member)
and renamed into place; a failed check deletes the part.
"""

import bisect
import hashlib
import importlib
import os
import re
import tempfile
import time
import zipfile
from contextlib import contextmanager, suppress
from pathlib import Path
from urllib.parse import unquote, urlsplit
from urllib.request import url2pathname

from tqdm.auto import tqdm

from ._download import PART, DownloadError, check_sha256, file_url, lock, remove_stale_parts

SCHEMES = ("http", "https", "file", "hf")
_BLOCK = 16 << 20
_MAX_GAP = 64 << 10
# Prefetched ranges: bytes of one request, and of the requests held in memory at once (then
# written to the reader's temporary file).
_PREFETCH_REQUEST = 4 << 20
_PREFETCH_HELD = 16 << 20
# A Hub dataset file: <endpoint>/datasets/<owner>/<name>/resolve/<revision>/<path>, or its
# hf://datasets/<owner>/<name>[@<revision>]/<path> form.
_HUB_URL = re.compile(
    r"^(?P<endpoint>https?://[^/]+)/datasets/(?P<repo>[^/]+/[^/]+)/resolve/(?P<revision>[^/]+)/"
    r"(?P<path>.+)$"
)
_HF_URL = re.compile(
    r"^hf://datasets/(?P<repo>[^/@]+/[^/@]+)(?:@(?P<revision>[^/]+))?/(?P<path>.+)$"
)


def require(module):
    """Import ``module`` of the extra ``skhmmgmr[fetch]``; ImportError naming it if missing."""
    try:
        return importlib.import_module(module)
    except ImportError as exc:
        raise ImportError(
            f"{module} is not installed. Reading remote archives needs the optional extra "
            "skhmmgmr[fetch] (fsspec, aiohttp, huggingface_hub): pip install 'skhmmgmr[fetch]'."
        ) from exc


def check_url(url):
    """Refuse a URL whose scheme is not supported, before any network access."""
    scheme = urlsplit(url).scheme
    if scheme not in SCHEMES:
        raise ValueError(f"Cannot download {url!r}: only {', '.join(SCHEMES)} URLs are supported.")


def remote_fs(url, timeout):
    """The fsspec file system and path of ``url``, waiting ``timeout`` seconds at each read."""
    check_url(url)
    fsspec = require("fsspec")
    parts = urlsplit(url)
    if parts.scheme == "file":
        return fsspec.filesystem("file"), url2pathname(parts.path)
    if parts.scheme == "hf":
        require("huggingface_hub")
        return fsspec.core.url_to_fs(url)
    aiohttp = require("aiohttp")
    limits = aiohttp.ClientTimeout(total=None, sock_connect=timeout, sock_read=timeout)
    fs = fsspec.filesystem("http", client_kwargs={"timeout": limits}, skip_instance_cache=True)
    return fs, url


def network_errors():
    """The exception types of a failed read: network, server, timeout, refused range."""
    errors = (OSError, TimeoutError, ValueError)
    with suppress(ImportError):
        import aiohttp

        errors += (aiohttp.ClientError,)
    return errors


def _causes(exc):
    """``exc`` and the exceptions it was raised from, outermost first."""
    seen = []
    while exc is not None and exc not in seen:
        seen.append(exc)
        exc = exc.__cause__ or exc.__context__
    return seen


def is_not_found(exc):
    """Whether the failure ``exc`` means the server has no such file (and nothing worse): a
    FileNotFoundError caused by nothing but an HTTP 404, or by nothing."""
    causes = [c for c in _causes(exc) if not isinstance(c, DownloadError)]
    return (
        bool(causes)
        and isinstance(causes[0], FileNotFoundError)
        and all(
            isinstance(c, FileNotFoundError) or getattr(c, "status", None) == 404
            for c in causes[1:]
        )
    )


# What a few of aiohttp's errors mean (their text names only the URL), by class name.
_REASONS = {
    "TooManyRedirects": "too many redirects (the server redirects in a loop)",
    "NonHttpUrlRedirectClientError": "redirected to {text}, which is not an http(s) URL: refused",
    "InvalidUrlRedirectClientError": "redirected to an invalid URL, {text}",
}
_NOT_FOUND = "no such file on the server (HTTP 404 or a missing local file)"


def _kind(exc):
    return next((c.__name__ for c in type(exc).__mro__ if c.__name__ in _REASONS), None)


def _reason(url, exc, timeout):
    """What went wrong, in words: ``exc``'s own text, or when that names only the URL (as
    fsspec's FileNotFoundError of any failed request does), what its causes say: a known
    aiohttp error, an HTTP status, a message of their own."""
    if isinstance(exc, TimeoutError):
        detail = f" ({exc})" if str(exc) else ""
        return f"timed out, no answer within timeout={timeout} s{detail}"
    for cause in _causes(exc):  # aiohttp errors whose text says nothing of what happened
        kind = _kind(cause)
        if kind is not None:
            return _REASONS[kind].format(text=str(cause))
    text = str(exc).strip().rstrip(".")
    if text.strip("'\"") not in ("", url):
        return text
    for cause in reversed(_causes(exc)[1:]):
        status = getattr(cause, "status", None)
        if isinstance(status, int) and status >= 400:
            return f"the server answered HTTP {status} {getattr(cause, 'message', '')}".strip()
        said = str(cause).strip().rstrip(".")
        if not isinstance(cause, FileNotFoundError) and said.strip("'\"") not in ("", url):
            return said  # such as "Can redirect only to http or https" (older aiohttp)
    if isinstance(exc, FileNotFoundError):
        return _NOT_FOUND
    return f"{type(exc).__name__} {text}".strip()


def failure(url, exc, timeout):
    """The DownloadError naming ``url`` and the reason for a network or server error ``exc``."""
    if isinstance(exc, DownloadError):
        return exc
    return DownloadError(f"Cannot download {url!r}: {_reason(url, exc, timeout).rstrip('.')}.")


@contextmanager
def naming(url, timeout):
    """Turn the network errors raised in the block into DownloadErrors naming ``url``."""
    try:
        yield
    except network_errors() as exc:
        raise failure(url, exc, timeout) from exc


class RangeReader:
    """A seekable, read-only remote file: reads in prefetched ranges come from a temporary file,
    others from the server (one Range request each).

    Parameters
    ----------
    fs, path : fsspec file system and path
        The file.
    url : str
        Its URL, the ``name`` of the reader (zipfile names its archive so).
    timeout : float
        Seconds to wait for the server at each read.

    Network and server errors are raised as DownloadErrors naming ``url``.
    """

    def __init__(self, fs, path, url, timeout):
        self.name, self.timeout = url, timeout
        self._fs, self._path = fs, path
        with naming(url, timeout):
            self.size = _size(fs, path, url)
            self._file = fs.open(path, "rb", size=self.size, cache_type="none")
        # start of every prefetched range -> (its offset in the spool file, its length)
        self._parts = {}
        self._starts = []
        self._spool = None
        self._pos = 0
        self.failure = None

    def prefetch(self, ranges):
        """Fetch the byte ranges ``[(start, end), ...]`` (end excluded) and keep them on disk:
        concurrent requests of at most ``_PREFETCH_REQUEST`` bytes, ``_PREFETCH_HELD`` bytes of
        them in memory at once."""
        if not ranges:
            return
        from fsspec.utils import merge_offset_ranges

        starts, ends = zip(*sorted(ranges), strict=True)
        _, starts, ends = merge_offset_ranges(
            [self._path] * len(starts), list(starts), list(ends), max_gap=_MAX_GAP
        )
        if self._spool is None:
            # closed by close(), which remote_zip calls on every way out
            self._spool = tempfile.TemporaryFile(prefix="skhmmgmr-ranges-")  # noqa: SIM115
        requests = [
            (a, min(a + _PREFETCH_REQUEST, end))
            for start, end in zip(starts, ends, strict=True)
            for a in range(start, end, _PREFETCH_REQUEST)
        ]
        offsets = {}
        for group in _groups(requests, _PREFETCH_HELD):
            with naming(self.name, self.timeout):
                blobs = self._fs.cat_ranges(
                    [self._path] * len(group), [a for a, _ in group], [b for _, b in group]
                )
                for blob in blobs:
                    if isinstance(blob, BaseException):
                        raise blob
            self._spool.seek(0, os.SEEK_END)
            for (a, b), blob in zip(group, blobs, strict=True):
                self._check(a, b, blob)
                offsets[a] = self._spool.tell()
                self._spool.write(blob)
            del blobs
        # the requests of a range were written one after the other: the range is one stretch
        for start, end in zip(starts, ends, strict=True):
            self._parts[start] = offsets[start], end - start
        self._starts = sorted(self._parts)

    def _check(self, start, end, data):
        if len(data) != end - start:
            raise DownloadError(
                f"Asked for bytes {start}-{end - 1} of {self.name!r}, got {len(data)} bytes: the "
                "connection was cut, or the server does not honour Range requests (then "
                "download the archive whole)."
            )

    def clear(self):
        """Forget the fetched ranges (and free their room on disk)."""
        self._parts.clear()
        self._starts = []
        if self._spool is not None:
            self._spool.seek(0)
            self._spool.truncate()

    def read(self, size=-1):
        end = self.size if size is None or size < 0 else min(self.size, self._pos + size)
        i = bisect.bisect_right(self._starts, self._pos) - 1
        if i >= 0:
            start = self._starts[i]
            offset, length = self._parts[start]
            if end <= start + length:
                self._spool.seek(offset + self._pos - start)
                out = self._spool.read(end - self._pos)
                self._pos = end
                return out
        try:
            with naming(self.name, self.timeout):
                self._file.seek(self._pos)
                out = self._file.read(end - self._pos)
            self._check(self._pos, end, out)
        except DownloadError as exc:  # zipfile turns an OSError into "not a zip file"
            self.failure = exc
            raise
        self._pos += len(out)
        return out

    def seek(self, offset, whence=os.SEEK_SET):
        base = {os.SEEK_SET: 0, os.SEEK_CUR: self._pos, os.SEEK_END: self.size}[whence]
        if base + offset < 0:
            raise ValueError(f"Cannot seek before the start of {self.name!r}.")
        self._pos = base + offset
        return self._pos

    def tell(self):
        return self._pos

    def seekable(self):
        return True

    def close(self):
        self.clear()
        if self._spool is not None:
            self._spool.close()
        self._file.close()


def _groups(requests, budget):
    """The ``(start, end)`` requests in consecutive groups of at most ``budget`` bytes (a
    request larger than that alone)."""
    group, held = [], 0
    for a, b in requests:
        if group and held + (b - a) > budget:
            yield group
            group, held = [], 0
        group.append((a, b))
        held += b - a
    if group:
        yield group


@contextmanager
def remote_zip(url, *, timeout):
    """Open the zip archive at ``url`` for range reads; yield the ZipFile and its RangeReader."""
    fs, path = remote_fs(url, timeout)
    reader = RangeReader(fs, path, url, timeout)
    try:
        try:
            archive = zipfile.ZipFile(reader)
        except (zipfile.BadZipFile, EOFError) as exc:
            if reader.failure is not None:
                raise reader.failure from exc
            raise DownloadError(f"{url!r} is not a readable zip archive ({exc}).") from exc
        with archive:
            yield archive, reader
    finally:
        reader.close()


def member_ranges(archive, infos):
    """The byte range of each member of ``infos`` in ``archive``: from its local header to the
    next member's (or the central directory); DownloadError naming a member whose header the
    central directory places at or after itself."""
    for info in infos:
        if not 0 <= info.header_offset < archive.start_dir:
            raise DownloadError(
                f"The central directory of {str(archive.filename)!r} places the member "
                f"{info.filename!r} at byte {info.header_offset}, outside the members (which "
                f"end at byte {archive.start_dir}): the archive is damaged."
            )
    offsets = sorted({i.header_offset for i in archive.infolist()} | {archive.start_dir})
    return [
        (i.header_offset, offsets[bisect.bisect_right(offsets, i.header_offset)]) for i in infos
    ]


def hub_sha256(url):
    """The SHA-256 the Hugging Face Hub publishes for the dataset file at ``url``.

    ``url`` is ``<endpoint>/datasets/<owner>/<name>/resolve/<revision>/<path>`` (the Hub, or a
    mirror with its layout and API) or ``hf://datasets/<owner>/<name>[@<revision>]/<path>``;
    any other URL gives None, and so does a file the Hub does not store with LFS. The digest
    is the ``lfs.sha256`` of the Hub's API (``HfApi.get_paths_info``), the one its LFS pointer
    and its ``X-Linked-ETag`` header give.
    """
    found = _HUB_URL.match(url) or _HF_URL.match(url)
    if found is None:
        return None
    hub = require("huggingface_hub")
    values = found.groupdict()
    revision = unquote(values["revision"]) if values["revision"] else None
    path = unquote(values["path"])
    try:
        api = hub.HfApi(endpoint=values.get("endpoint"))
        infos = api.get_paths_info(values["repo"], [path], repo_type="dataset", revision=revision)
    except Exception as exc:  # the Hub client's own errors (HTTP, network, not found)
        raise DownloadError(
            f"Cannot read the SHA-256 of {url!r} from the Hugging Face Hub's API: {exc}."
        ) from exc
    if not infos:
        raise DownloadError(f"The Hugging Face Hub has no file {path!r} in {values['repo']}.")
    lfs = getattr(infos[0], "lfs", None)
    return None if lfs is None else check_sha256(lfs["sha256"], path)


def read_manifest(base_url, name="SHA256SUMS", *, timeout=60.0):
    """Read a checksum manifest in ``sha256sum`` format from the folder ``base_url``.

    Parameters
    ----------
    base_url : str
        An ``http``, ``https``, ``file`` or ``hf`` URL of a folder.
    name : str, default="SHA256SUMS"
        File name of the manifest in that folder.
    timeout : float, default=60.0
        Seconds to wait for the server at each read.

    Returns
    -------
    checksums : dict of str to str or None
        Lower-case hexadecimal SHA-256 digest by file name, or None when the folder has no
        manifest.

    Raises
    ------
    ValueError
        When a line of the manifest is malformed.
    DownloadError
        An OSError naming the manifest's URL, when the server or network fails (other than
        by not having the manifest).
    """
    url = file_url(base_url, name)
    fs, path = remote_fs(url, timeout)
    try:
        with naming(url, timeout):
            data = fs.cat_file(path)
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ValueError(f"The manifest {url!r} is not UTF-8 text ({exc}).") from None
    except DownloadError as exc:
        if is_not_found(exc):
            return None
        raise
    checksums = {}
    for line_number, line in enumerate(text.splitlines(), start=1):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        parts = line.split(maxsplit=1)
        try:
            if len(parts) != 2:
                raise ValueError("it is not '<SHA-256> <file name>'")
            digest, file_name = parts
            checksums[file_name.strip().lstrip("*")] = check_sha256(digest, file_name)
        except ValueError as exc:
            raise ValueError(
                f"Line {line_number} of the manifest {url!r} is malformed ({exc}): {line[:200]!r}."
            ) from None
    return checksums


def download(url, path, *, sha256=None, timeout=60.0, check=None, progress=False):
    """Download ``url`` to ``path``, resuming an interrupted download of it.

    The bytes go to the hidden file ``.<name>.part`` beside ``path``, appended block by block
    (one Range request each) from where an earlier, interrupted download stopped. Once complete,
    its SHA-256 must match ``sha256`` (when given) and ``check`` must accept it; then it is
    renamed to ``path`` (atomically), so ``path`` either does not exist or holds the complete,
    verified file. A failed check deletes the part; a failed transfer (network, server,
    timeout, cut connection, ``KeyboardInterrupt``) keeps it, for the next call to resume.

    Parameters
    ----------
    url : str
        An ``http``, ``https``, ``file`` or ``hf`` URL.
    path : str or path-like
        Where the file goes; its folder is created if needed.
    sha256 : str, default=None
        Expected hexadecimal SHA-256 digest of the file; not checked when None.
    timeout : float, default=60.0
        Seconds to wait for the server at each read.
    check : callable, default=None
        Called with the path of the complete part before it is renamed; raises a ValueError
        saying what is wrong to refuse it (such as :func:`._download.check_zip`).
    progress : bool, default=False
        Whether to show a progress bar (tqdm).

    Returns
    -------
    sha256 : str
        Hexadecimal SHA-256 digest of the downloaded file.

    Raises
    ------
    DownloadError
        An OSError naming ``url`` and what failed: the server or network (including timeouts
        and HTTP errors), a cut transfer, a server ignoring Range requests, a checksum
        mismatch, ``check``, or another process downloading the same file.
    """
    path = Path(path)
    expected = None if sha256 is None else check_sha256(sha256, path.name)
    fs, remote = remote_fs(url, timeout)
    path.parent.mkdir(parents=True, exist_ok=True)
    remove_stale_parts(path, time.time())
    with naming(url, timeout):
        size = _size(fs, remote, url)
    part = path.with_name(f".{path.name}{PART}")
    with open(part, "ab") as out:
        try:
            lock(out)
        except OSError as exc:
            raise DownloadError(
                f"{str(part)!r} is being written by another download of {url!r}: wait for it."
            ) from exc
        if out.tell() > size:  # not a part of this file
            out.truncate(0)
            out.seek(0)
        digest = _digest_of(part)
        try:
            _append(fs, remote, url, out, digest, size, progress, timeout)
        except DownloadError as exc:
            if out.tell() == 0:  # nothing to resume
                out.close()
                part.unlink(missing_ok=True)
                raise
            raise DownloadError(
                f"{exc} The first {out.tell()} of {size} bytes are kept in {str(part)!r}: call "
                "again to resume."
            ) from exc
        actual = digest.hexdigest()
        try:
            if expected is not None and actual != expected:
                raise DownloadError(
                    f"Checksum mismatch for {url!r}: expected SHA-256 {expected}, got {actual}. "
                    "The file is corrupted or is not the expected version; nothing was kept."
                )
            if check is not None:
                try:
                    check(part)
                except ValueError as exc:
                    raise DownloadError(
                        f"The download of {url!r} is refused: {exc}. Nothing was kept; try "
                        "again, or check the URL."
                    ) from exc
        except DownloadError:
            part.unlink(missing_ok=True)
            raise
    os.replace(part, path)
    return actual


def _digest_of(path):
    digest = hashlib.sha256()
    with open(path, "rb") as file:
        for block in iter(lambda: file.read(_BLOCK), b""):
            digest.update(block)
    return digest


def _size(fs, path, url):
    size = fs.size(path)
    if size is None:
        raise DownloadError(
            f"The server gives no length for {url!r}: it cannot be read by byte ranges nor "
            "downloaded resumably."
        )
    return size


def _append(fs, remote, url, out, digest, size, progress, timeout):
    """Append the bytes of ``remote`` from the end of ``out`` on, one Range request a block."""
    done = out.tell()
    with (
        naming(url, timeout),
        fs.open(remote, "rb", size=size, cache_type="none") as source,
        tqdm(
            total=size,
            initial=done,
            unit="B",
            unit_scale=True,
            desc=Path(urlsplit(url).path).name,
            disable=not progress,
        ) as bar,
    ):
        source.seek(done)
        while done < size:
            wanted = min(_BLOCK, size - done)
            block = source.read(wanted)
            if len(block) != wanted:
                raise DownloadError(
                    f"Download of {url!r} stopped at byte {done}: the connection was cut, or "
                    f"the server sent {len(block)} bytes for a range of {wanted}."
                )
            out.write(block)
            out.flush()
            digest.update(block)
            done += len(block)
            bar.update(len(block))
