"""Verify and unpack archives, and write files, without ever leaving a half-written one in place.

Everything here is generic and needs no network: the remote side (range reads, resumable
downloads, checksums the server publishes) is :mod:`._remote`, and the dataset fetchers (such as
:mod:`._comma2k19._fetch` for comma2k19) add the URLs, file names and archive layouts.
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
# What an unpacked member may hold unless the caller says less: its size, and for a compressed
# zip member its size over its compressed size (zlib reaches about 1000 on zeros; measured data
# and logs stay below 20).
MAX_MEMBER_SIZE = 1 << 30
MAX_RATIO = 100.0
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


def extract(archive, destinations, *, max_size=MAX_MEMBER_SIZE, max_ratio=MAX_RATIO):
    """Unpack selected regular files of a zip or tar archive.

    Parameters
    ----------
    archive : path-like or zipfile.ZipFile
        The zip or tar (optionally compressed) archive, or a zip archive already open (such as
        one read by byte ranges, see :mod:`._remote`; its ``filename`` names it in errors).
    destinations : callable
        Called with the path parts of every regular file; returns the path where the file
        goes, or None to skip it. Links and special files are never unpacked.
    max_size : int or callable, default=MAX_MEMBER_SIZE
        The most bytes a member unpacked may hold, or a callable giving it from the member's
        path parts.
    max_ratio : float, default=MAX_RATIO
        The largest unpacked size of a compressed zip member over its compressed size.

    Raises
    ------
    ValueError
        When the file is neither a zip nor a tar archive, or a member name would be written
        outside the target folder.
    DownloadError
        Naming the member and the archive, when a zip member fails its CRC-32 check or cannot
        be decompressed, or would unpack to more than ``max_size`` bytes or ``max_ratio``
        times its compressed size (checked on the sizes the archive declares, before anything
        is read, and again on the bytes written).

    Notes
    -----
    Files are written in place as they come: use :func:`extract_folders` so that a failure
    never leaves a partly unpacked folder where a cache expects a complete one.
    """
    limit = max_size if callable(max_size) else (lambda parts: max_size)
    if isinstance(archive, zipfile.ZipFile):
        _extract_zip(archive, destinations, str(archive.filename), limit, max_ratio)
        return
    archive = Path(archive)
    if zipfile.is_zipfile(archive):
        with zipfile.ZipFile(archive) as zf:
            _extract_zip(zf, destinations, str(archive), limit, max_ratio)
        return
    if tarfile.is_tarfile(archive):
        with tarfile.open(archive) as tf:
            for member in tf:
                parts = member_parts(member.name, archive.name)
                if not member.isfile():
                    continue
                target = destinations(parts)
                if target is not None:
                    cap = _check_member(member.name, str(archive), member.size, limit(parts))
                    _copy_member(tf.extractfile(member), target, cap, member.name, str(archive))
        return
    raise ValueError(f"{archive} is neither a zip nor a tar archive.")


def _check_member(member, archive, size, cap, compressed=None, max_ratio=None):
    """Refuse a member whose declared unpacked size is over ``cap`` bytes, or (compressed)
    over ``max_ratio`` times its compressed size; return the bytes it may write."""
    if size > cap:
        raise DownloadError(
            f"The member {member!r} of the archive {archive!r} would unpack to {size} bytes, "
            f"more than the {cap} such a member may hold: refusing the archive (a damaged or "
            "hostile file); nothing of it was kept."
        )
    if compressed is not None and size > max_ratio * max(compressed, 1):
        raise DownloadError(
            f"The member {member!r} of the archive {archive!r} would unpack to {size} bytes "
            f"from {compressed}, {size / max(compressed, 1):.0f} times its compressed size "
            f"(at most {max_ratio:g}): refusing the archive (a compression bomb?); nothing of it "
            "was kept."
        )
    return size


def _extract_zip(zf, destinations, name, limit, max_ratio):
    for info in zf.infolist():
        if info.is_dir():
            continue
        # A zip written on Unix can mark a member as a symbolic link.
        if (info.external_attr >> 16) & 0o170000 == 0o120000:
            continue
        parts = member_parts(info.filename, Path(name).name)
        target = destinations(parts)
        if target is None:
            continue
        compressed = None if info.compress_type == zipfile.ZIP_STORED else info.compress_size
        cap = _check_member(
            info.filename, name, info.file_size, limit(parts), compressed, max_ratio
        )
        try:
            _copy_member(zf.open(info), target, cap, info.filename, name)
        except (zipfile.BadZipFile, zlib.error, EOFError) as exc:
            raise DownloadError(
                f"The member {info.filename!r} of the archive {name!r} is damaged ({exc}); "
                "nothing of it was kept."
            ) from exc


def _copy_member(source, target, cap, member, archive):
    """Copy ``source`` to ``target`` in blocks, refusing more than ``cap`` bytes."""
    target = Path(target)
    written = 0
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        out = open(target, "wb")  # noqa: SIM115 (closed below; open's own errors named here)
    except OSError as exc:  # a name too long, a file where a folder must be, a full disk
        raise DownloadError(
            f"Cannot unpack the member {member!r} of the archive {archive!r}: "
            f"{exc.strerror or exc}; nothing of the archive was kept."
        ) from exc
    with source, out:
        while block := source.read(_CHUNK_SIZE):
            written += len(block)
            if written > cap:
                raise DownloadError(
                    f"The member {member!r} of the archive {archive!r} unpacks to more than the "
                    f"{cap} bytes it declares: refusing the archive; nothing of it was kept."
                )
            out.write(block)


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


def extract_folders(archive, root, folder_of, *, max_size=MAX_MEMBER_SIZE, max_ratio=MAX_RATIO):
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
    max_size, max_ratio
        What a member may hold, see :func:`extract`; a member over them refuses the whole
        archive and nothing is kept.

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

        extract(archive, destination, max_size=max_size, max_ratio=max_ratio)
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
