"""Verify and unpack archives, and write files, without ever leaving a half-written one in place.

Everything here is generic and needs no network: the remote side (range reads, resumable
downloads, checksums the server publishes) is :mod:`._remote`, and the dataset fetchers (such as
:mod:`._fetch` for comma2k19) add the URLs, file names and archive layouts.
"""

import os
import re
import shutil
import tarfile
import tempfile
import zipfile
import zlib
from contextlib import contextmanager
from pathlib import Path, PurePosixPath

try:
    import fcntl
except ImportError:  # Windows
    fcntl = None

_CHUNK_SIZE = 1 << 20
PART = ".part"
_SHA256 = re.compile(r"^[0-9a-fA-F]{64}$")


def check_sha256(sha256, name):
    """Return ``sha256`` in lower case, refusing what is not 64 hexadecimal digits."""
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
    # Not urljoin: it ignores the base of schemes it does not know, such as hf://.
    return base_url + name if base_url.endswith("/") else f"{base_url}/{name}"


class DownloadError(OSError):
    """A download failed or gave a damaged file; the message names the URL and what failed."""


def lock(file):
    """Hold an advisory lock on an open file, telling other processes it is being written.

    Raises BlockingIOError if another process holds it. Without POSIX locks (Windows), an
    open file cannot be deleted anyway, which is all :func:`remove_stale_parts` needs.
    """
    if fcntl is not None:
        fcntl.flock(file.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)


def remove_stale_parts(path, before):
    """Delete the temporary files that dead downloads of ``path`` left in its folder.

    Versions before range reads wrote a download to a hidden ``.<name>.<8 characters>.part``
    file that was never resumed, up to the size of the whole file (downloads now go to one
    ``.<name>.part`` that the next download resumes). Those of ``path`` last written before the
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
    pattern = re.compile(rf"^\.{re.escape(path.name)}\.[a-z0-9_]{{8}}{re.escape(PART)}$")
    if not path.parent.is_dir():
        return
    for candidate in path.parent.iterdir():
        if not pattern.match(candidate.name):
            continue
        try:
            if candidate.stat().st_mtime >= before:
                continue
            with open(candidate, "rb") as file:
                lock(file)
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


def member_parts(name, archive):
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
            return [member_parts(i.filename, archive.name) for i in infos if not i.is_dir()]
    if tarfile.is_tarfile(archive):
        with tarfile.open(archive) as tf:
            members = tf.getmembers()
            for m in members:
                member_parts(m.name, archive.name)
            return [member_parts(m.name, archive.name) for m in members if m.isfile()]
    raise ValueError(f"{archive} is neither a zip nor a tar archive.")


def extract(archive, destinations):
    """Unpack selected regular files of a zip or tar archive.

    Parameters
    ----------
    archive : path-like or zipfile.ZipFile
        The zip or tar (optionally compressed) archive, or a zip archive already open (such as
        one read by byte ranges, see :mod:`._remote`; its ``filename`` names it in errors).
    destinations : callable
        Called with the path parts of every regular file; returns the path where the file
        goes, or None to skip it. Links and special files are never unpacked.

    Raises
    ------
    ValueError
        When the file is neither a zip nor a tar archive, or a member name would be written
        outside the target folder.
    DownloadError
        Naming the member and the archive, when a zip member fails its CRC-32 check or cannot
        be decompressed.

    Notes
    -----
    Files are written in place as they come: use :func:`extract_folders` so that a failure
    never leaves a partly unpacked folder where a cache expects a complete one.
    """
    if isinstance(archive, zipfile.ZipFile):
        _extract_zip(archive, destinations, str(archive.filename))
        return
    archive = Path(archive)
    if zipfile.is_zipfile(archive):
        with zipfile.ZipFile(archive) as zf:
            _extract_zip(zf, destinations, str(archive))
        return
    if tarfile.is_tarfile(archive):
        with tarfile.open(archive) as tf:
            for member in tf:
                parts = member_parts(member.name, archive.name)
                if not member.isfile():
                    continue
                target = destinations(parts)
                if target is not None:
                    _copy_member(tf.extractfile(member), target)
        return
    raise ValueError(f"{archive} is neither a zip nor a tar archive.")


def _extract_zip(zf, destinations, name):
    for info in zf.infolist():
        if info.is_dir():
            continue
        # A zip written on Unix can mark a member as a symbolic link.
        if (info.external_attr >> 16) & 0o170000 == 0o120000:
            continue
        target = destinations(member_parts(info.filename, Path(name).name))
        if target is None:
            continue
        try:
            _copy_member(zf.open(info), target)
        except (zipfile.BadZipFile, zlib.error, EOFError) as exc:
            raise DownloadError(
                f"The member {info.filename!r} of the archive {name!r} is damaged ({exc}); "
                "nothing of it was kept."
            ) from exc


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
    archive : path-like or zipfile.ZipFile
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
