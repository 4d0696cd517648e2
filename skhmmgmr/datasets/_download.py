"""Download, verify and unpack files without ever leaving a half-written one in place.

Everything here is generic: the dataset fetchers (such as :mod:`._fetch` for comma2k19) add the
URLs, file names and archive layouts.
"""

import hashlib
import os
import re
import shutil
import tarfile
import tempfile
import time
import zipfile
import zlib
from contextlib import contextmanager, suppress
from http.client import HTTPException, IncompleteRead
from pathlib import Path, PurePosixPath
from urllib.error import HTTPError, URLError
from urllib.parse import urljoin, urlsplit
from urllib.request import urlopen

try:
    import fcntl
except ImportError:  # Windows
    fcntl = None

_CHUNK_SIZE = 1 << 20
_PART = ".part"
_SCHEMES = ("http", "https", "file")
_SHA256 = re.compile(r"^[0-9a-fA-F]{64}$")


def _check_url(url):
    scheme = urlsplit(url).scheme
    if scheme not in _SCHEMES:
        raise ValueError(f"Cannot download {url!r}: only {', '.join(_SCHEMES)} URLs are supported.")


def _check_sha256(sha256, name):
    if not isinstance(sha256, str) or not _SHA256.match(sha256):
        raise ValueError(
            f"The SHA-256 checksum given for {name!r} must be 64 hexadecimal digits, "
            f"got {sha256!r}."
        )
    return sha256.lower()


def file_url(base_url, name):
    """Return the URL of the file ``name`` in the folder ``base_url``.

    Parameters
    ----------
    base_url : str
        URL of a folder, with or without the final ``/``.
    name : str
        File name in that folder.

    Returns
    -------
    url : str
        The file's URL.
    """
    if not base_url.endswith("/"):
        base_url += "/"
    return urljoin(base_url, name)


class DownloadError(OSError):
    """A download failed or gave a damaged file; the message names the URL and what failed."""


def _failure(url, exc, timeout):
    """The DownloadError naming ``url`` for a network or server error."""
    reason = exc.reason if isinstance(exc, URLError) and not isinstance(exc, HTTPError) else exc
    if isinstance(reason, TimeoutError):
        reason = f"no answer within timeout={timeout} s ({reason or 'timed out'})"
    return DownloadError(f"Cannot download {url!r}: {reason}.")


def _lock(file):
    """Hold an advisory lock on an open file, telling other processes it is being written.

    Raises BlockingIOError if another process holds it. Without POSIX locks (Windows), an
    open file cannot be deleted anyway, which is all :func:`remove_stale_parts` needs.
    """
    if fcntl is not None:
        fcntl.flock(file.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)


def remove_stale_parts(path, before):
    """Delete the temporary files that dead downloads of ``path`` left in its folder.

    A download killed by the system (a ``KeyboardInterrupt`` cleans up) leaves its hidden
    ``.part`` file, up to the size of the whole file. Those of ``path`` last written before the
    time ``before`` (seconds since the epoch) are deleted, except those a running download
    still holds (locked, or open on Windows).

    Parameters
    ----------
    path : path-like
        The file the downloads were for.
    before : float
        Start of the current attempt, as :func:`time.time` gives it.
    """
    path = Path(path)
    pattern = re.compile(rf"^\.{re.escape(path.name)}\.[a-z0-9_]{{8}}{re.escape(_PART)}$")
    if not path.parent.is_dir():
        return
    for candidate in path.parent.iterdir():
        if not pattern.match(candidate.name):
            continue
        try:
            if candidate.stat().st_mtime >= before:
                continue
            with open(candidate, "rb") as file:
                _lock(file)
                candidate.unlink()
        except OSError:  # held by a running download, or already gone
            continue


def check_zip(path):
    """Raise ValueError unless ``path`` is a complete zip archive whose members are intact.

    The central directory must be readable and every member must pass its CRC-32 check, so a
    cut download or another file served in its place (such as an HTML error page) is refused
    even when no checksum is known. Reads the whole archive.

    Parameters
    ----------
    path : path-like
        The file to check.
    """
    try:
        with zipfile.ZipFile(path) as zf:
            damaged = zf.testzip()
    except (zipfile.BadZipFile, EOFError, zlib.error, NotImplementedError) as exc:
        raise ValueError(f"it is not a readable zip archive ({exc})") from exc
    if damaged is not None:
        raise ValueError(f"its member {damaged!r} fails its CRC check (damaged data)")


def _receive(url, out, timeout):
    """Write the body of ``url`` to ``out``; return its SHA-256 and the length announced."""
    digest = hashlib.sha256()
    n_bytes = 0
    try:
        with urlopen(url, timeout=timeout) as response:
            length = response.headers.get("Content-Length")
            for block in iter(lambda: response.read(_CHUNK_SIZE), b""):
                out.write(block)
                digest.update(block)
                n_bytes += len(block)
    except IncompleteRead as exc:
        raise DownloadError(
            f"Download of {url!r} stopped after {n_bytes + len(exc.partial)} bytes: the "
            "connection was cut before the end of the file; nothing was kept. Try again."
        ) from exc
    except (OSError, HTTPException) as exc:
        raise _failure(url, exc, timeout) from exc
    if length is not None and n_bytes != int(length):
        raise DownloadError(
            f"Download of {url!r} stopped after {n_bytes} of {int(length)} bytes; "
            "nothing was kept. Try again."
        )
    return digest.hexdigest()


def download(url, path, *, sha256=None, timeout=60.0, check=None):
    """Download ``url`` to ``path`` through a temporary file in the same folder.

    The bytes go to a hidden temporary file next to ``path``, which is renamed to ``path``
    (atomically) only once the whole body was received (as long as the server announced, and
    without a cut connection), its checksum matches when ``sha256`` is given, and ``check``
    accepts it. On any failure, including a ``KeyboardInterrupt``, the temporary file is
    deleted, so ``path`` either does not exist or holds the complete, verified file. The
    temporary files of earlier downloads of ``path`` that were killed are deleted (see
    :func:`remove_stale_parts`); a download never resumes one.

    Parameters
    ----------
    url : str
        An ``http``, ``https`` or ``file`` URL.
    path : str or path-like
        Where the file goes; its folder is created if needed.
    sha256 : str, default=None
        Expected hexadecimal SHA-256 digest of the file; not checked when None.
    timeout : float, default=60.0
        Seconds to wait for the server at each read.
    check : callable, default=None
        Called with the path of the complete temporary file before it is renamed; raises a
        ValueError saying what is wrong to refuse it (such as :func:`check_zip`).

    Returns
    -------
    sha256 : str
        Hexadecimal SHA-256 digest of the downloaded file.

    Raises
    ------
    DownloadError
        An OSError naming ``url`` and what failed: the server or network (including timeouts
        and HTTP errors), a cut transfer, a checksum mismatch, or ``check``.
    """
    _check_url(url)
    path = Path(path)
    expected = None if sha256 is None else _check_sha256(sha256, path.name)
    path.parent.mkdir(parents=True, exist_ok=True)
    started = time.time()
    remove_stale_parts(path, started)
    try:
        with atomic_open(path, "wb", suffix=_PART) as out:
            with suppress(OSError):  # a file system without locks: cleaners then keep it
                _lock(out)
            actual = _receive(url, out, timeout)
            out.flush()
            if expected is not None and actual != expected:
                raise DownloadError(
                    f"Checksum mismatch for {url!r}: expected SHA-256 {expected}, got {actual}. "
                    "The file is corrupted or is not the expected version; nothing was kept."
                )
            if check is not None:
                try:
                    check(out.name)
                except ValueError as exc:
                    raise DownloadError(
                        f"The download of {url!r} is refused: {exc}. Nothing was kept; try "
                        "again, or check the URL."
                    ) from exc
    finally:
        remove_stale_parts(path, started)
    return actual


def read_manifest(base_url, name="SHA256SUMS", *, timeout=60.0):
    """Read a checksum manifest in ``sha256sum`` format from the folder ``base_url``.

    Parameters
    ----------
    base_url : str
        An ``http``, ``https`` or ``file`` URL of a folder.
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
    _check_url(url)
    try:
        with urlopen(url, timeout=timeout) as response:
            text = response.read().decode("utf-8")
    except HTTPError as exc:
        if exc.code == 404:
            return None
        raise _failure(url, exc, timeout) from exc
    except URLError as exc:
        if isinstance(exc.reason, FileNotFoundError):
            return None
        raise _failure(url, exc, timeout) from exc
    except (OSError, HTTPException) as exc:
        raise _failure(url, exc, timeout) from exc
    checksums = {}
    for line_number, line in enumerate(text.splitlines(), start=1):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        parts = line.split(maxsplit=1)
        if len(parts) != 2:
            raise ValueError(f"Line {line_number} of the manifest {url!r} is malformed: {line!r}.")
        digest, file_name = parts
        checksums[file_name.strip().lstrip("*")] = _check_sha256(digest, file_name)
    return checksums


def _member_parts(name, archive):
    """Split an archive member name into path parts, refusing names that escape the folder."""
    posix = PurePosixPath(name.replace("\\", "/"))
    parts = [p for p in posix.parts if p not in ("", ".")]
    if posix.is_absolute() or ".." in parts or (parts and re.match(r"^[A-Za-z]:$", parts[0])):
        raise ValueError(
            f"Refusing to unpack {archive}: its member {name!r} would be written outside the "
            "target folder."
        )
    return tuple(parts)


def list_members(archive):
    """Return the path parts of every regular file in a zip or tar archive.

    Parameters
    ----------
    archive : path-like
        The zip or tar (optionally compressed) archive.

    Returns
    -------
    members : list of tuple of str
        The path parts of each regular file, in archive order.

    Raises
    ------
    ValueError
        When the file is neither a zip nor a tar archive, or a member name is absolute or
        contains ``..``.
    """
    archive = Path(archive)
    if zipfile.is_zipfile(archive):
        with zipfile.ZipFile(archive) as zf:
            infos = zf.infolist()
            return [_member_parts(i.filename, archive.name) for i in infos if not i.is_dir()]
    if tarfile.is_tarfile(archive):
        with tarfile.open(archive) as tf:
            members = tf.getmembers()
            for m in members:
                _member_parts(m.name, archive.name)
            return [_member_parts(m.name, archive.name) for m in members if m.isfile()]
    raise ValueError(f"{archive} is neither a zip nor a tar archive.")


def extract(archive, destinations):
    """Unpack selected regular files of a zip or tar archive.

    Parameters
    ----------
    archive : path-like
        The zip or tar (optionally compressed) archive.
    destinations : callable
        Called with the path parts of every regular file; returns the path where the file
        goes, or None to skip it. Links and special files are never unpacked.

    Raises
    ------
    ValueError
        When the file is neither a zip nor a tar archive, or a member name would be written
        outside the target folder.

    Notes
    -----
    Files are written in place as they come: use :func:`extract_folders` so that a failure
    never leaves a partly unpacked folder where a cache expects a complete one.
    """
    archive = Path(archive)
    if zipfile.is_zipfile(archive):
        with zipfile.ZipFile(archive) as zf:
            for info in zf.infolist():
                if info.is_dir():
                    continue
                # A zip written on Unix can mark a member as a symbolic link.
                if (info.external_attr >> 16) & 0o170000 == 0o120000:
                    continue
                target = destinations(_member_parts(info.filename, archive.name))
                if target is not None:
                    _copy_member(zf.open(info), target)
        return
    if tarfile.is_tarfile(archive):
        with tarfile.open(archive) as tf:
            for member in tf:
                parts = _member_parts(member.name, archive.name)
                if not member.isfile():
                    continue
                target = destinations(parts)
                if target is not None:
                    _copy_member(tf.extractfile(member), target)
        return
    raise ValueError(f"{archive} is neither a zip nor a tar archive.")


def _copy_member(source, target):
    target = Path(target)
    target.parent.mkdir(parents=True, exist_ok=True)
    with source, open(target, "wb") as out:
        shutil.copyfileobj(source, out, _CHUNK_SIZE)


@contextmanager
def atomic_open(path, mode="w", *, suffix=""):
    """Open a hidden temporary file next to ``path``, renamed to ``path`` on success.

    Parameters
    ----------
    path : str or path-like
        The file to write; its folder must exist.
    mode : {"w", "wb"}, default="w"
        Text or binary.
    suffix : str, default=""
        End of the temporary file's name.

    Yields
    ------
    file : file object
        The temporary file; its ``name`` is its path. When the ``with`` block ends normally,
        the file is closed and renamed (atomically) to ``path``; when it raises anything,
        including a ``KeyboardInterrupt``, the temporary file is deleted and ``path`` is left as
        it was.
    """
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=suffix, dir=path.parent)
    os.close(fd)
    try:
        with open(tmp, mode) as file:
            yield file
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def extract_folders(archive, root, folder_of):
    """Unpack members of an archive into folders of ``root``, each renamed into place whole.

    Parameters
    ----------
    archive : path-like
        The zip or tar archive, see :func:`extract`.
    root : path-like
        The existing folder that receives the unpacked folders.
    folder_of : callable
        Called with the path parts of every regular file of the archive; returns the folder
        (relative to ``root``) the file belongs to and its path parts inside that folder, or
        None to skip the file.

    Notes
    -----
    The files go to a hidden temporary folder in ``root`` first, and each folder is renamed into
    place only once the whole archive is unpacked: a folder of ``root`` is always complete. A
    folder already in ``root`` (unpacked meanwhile by another process) is kept as it is.
    """
    root = Path(root)
    tmp = Path(tempfile.mkdtemp(prefix=".unpacking-", dir=root))
    folders = {}
    try:

        def destination(parts):
            found = folder_of(parts)
            if found is None:
                return None
            folder, inside = Path(found[0]), found[1]
            folders.setdefault(folder)
            return (tmp / folder).joinpath(*inside)

        extract(archive, destination)
        for folder in folders:
            final = root / folder
            final.parent.mkdir(parents=True, exist_ok=True)
            try:
                (tmp / folder).rename(final)
            except OSError:
                if not final.is_dir():
                    raise
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
