"""Writing output files: one rule for every writer of the package.

Every file the package writes for a user (the C export, the command line's outputs, the model
files, the FMU) goes through these two functions, so that the rules hold everywhere at once:

- :func:`check_output_paths`, before anything is computed or created: a missing folder is
  created only when the caller allows it, an existing file is refused unless ``overwrite``, a
  folder where a file is wanted is refused; the error names the option (``--output``,
  ``directory``...) the path came from.
- :func:`write_atomically`, to write: the content goes first to a temporary file created
  *exclusively* beside the target (``O_CREAT | O_EXCL`` at a random name, so that a file or
  symbolic link planted at a predictable name is never followed), then replaces the target in
  one rename; the temporary file is removed when the write fails or is interrupted.
"""

import os
import secrets
from pathlib import Path

__all__ = ["check_output_paths", "write_atomically"]

_EXCLUSIVE = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0)


def _label(option, path):
    return f"{option} {path}" if option else str(path)


def check_output_paths(paths, *, overwrite, option=None, create_folders=True):
    """Check that ``paths`` may be written, before any work or any folder is made.

    Parameters
    ----------
    paths : sequence of path-like
        The files that will be written.
    overwrite : bool
        Whether an existing file may be replaced.
    option : str, optional
        The parameter or command-line option the paths come from, named in every error.
    create_folders : bool, default=True
        Whether a missing parent folder may be created (by :func:`write_atomically`); when
        False a missing folder is refused.

    Raises
    ------
    FileExistsError
        For an existing file and ``overwrite=False``.
    IsADirectoryError
        For a path that is a folder.
    NotADirectoryError
        For a parent that exists and is not a folder, or that is missing and
        ``create_folders=False``.
    PermissionError
        For an existing parent folder that cannot be written.
    """
    for path in map(Path, paths):
        label = _label(option, path)
        if path.is_dir():
            raise IsADirectoryError(f"{label} is a folder; name a file")
        parent = path.parent
        existing = parent
        while not existing.exists() and existing != existing.parent:
            existing = existing.parent
        if existing != parent:
            if not create_folders:
                raise NotADirectoryError(f"{label}: the folder {parent} does not exist")
            if not existing.is_dir():
                raise NotADirectoryError(f"{label}: {existing} is not a folder")
        elif not parent.is_dir():
            raise NotADirectoryError(f"{label}: {parent} is not a folder")
        if not os.access(existing, os.W_OK | os.X_OK):
            raise PermissionError(f"{label}: the folder {existing} is not writable")
        if os.path.lexists(path) and not overwrite:
            hint = "pass --overwrite" if option and option.startswith("--") else "overwrite=True"
            raise FileExistsError(f"{label} exists; {hint} to replace it")


def _exclusive_temporary(path):
    """Create and close an empty file beside ``path`` at a fresh random name, exclusively."""
    for _ in range(100):
        # ends with the target's name, so that a writer that infers the format or the
        # compression from the suffix (pandas) infers the target's
        candidate = path.with_name(f".{secrets.token_hex(8)}.partial-{path.name}")
        try:
            descriptor = os.open(
                candidate,
                os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0),
                0o666,
            )
        except FileExistsError:
            continue
        os.close(descriptor)
        return candidate
    raise FileExistsError(f"cannot create a temporary file beside {path}")


def write_atomically(path, content=None, *, write=None, encoding="utf-8"):
    """Write ``path`` completely or not at all, never through a planted file or link.

    Parameters
    ----------
    path : path-like
        The target; its missing parent folders are created.
    content : str or bytes, optional
        What to write. Exactly one of ``content`` and ``write`` is given.
    write : callable, optional
        ``write(temporary_path)`` writes the content to the path it is given (for writers
        that take a path, as ``DataFrame.to_csv`` does).
    encoding : str, default="utf-8"
        The encoding of a ``str`` content.

    Returns
    -------
    path : Path
        The target written.
    """
    if (content is None) == (write is None):
        raise TypeError("give exactly one of content and write")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    temporary = _exclusive_temporary(path)
    try:
        if write is not None:
            write(temporary)
        else:
            data = content.encode(encoding) if isinstance(content, str) else bytes(content)
            with open(temporary, "r+b") as file:
                file.write(data)
        os.replace(temporary, path)
    finally:
        temporary.unlink(missing_ok=True)
    return path
