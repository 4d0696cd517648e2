"""Files of the command line: inputs read in the package's one row order, outputs guarded.

Inputs: a CSV or Parquet table, read by the loaders' reader (recording ids as text, every error
naming the file); its rows put in the order of :func:`~skhmmgmr.datasets.load_recordings`
(recordings contiguous in order of first appearance, rows sorted by time, a repeated time
refused); and the model file (a regressor or a torque pipeline), read only as the portable JSON
format, never unpickled.

Outputs: checked before the run, so that a long run never ends in an error it could have
reported at once (the folder exists and is writable, an input is never overwritten, a user's
file or folder only with ``--overwrite``), then written beside the target and swapped in when
complete, so that an interrupted run leaves the previous file as it was.

Splits: data without a usable split column are split by recording at random
(:func:`assign_splits`).
"""

import os
from pathlib import Path

import numpy as np

from .._core._schema import DRIVER, RECORDING, SPLIT, TIME
from ..datasets._frame import tidy_frame, time_order
from ..datasets._recordings import read_table
from ._report import check_replaceable


class CommandError(Exception):
    """A user-facing error: printed without a traceback, exit code 2."""


def read_data(path, *id_columns):
    """The table of a CSV or Parquet file; the id columns, driver and split read as text."""
    path = Path(path)
    if not path.exists():
        raise CommandError(f"data file not found: {path}")
    try:
        return read_table(path, (*id_columns, DRIVER, SPLIT))
    except (ValueError, OSError) as exc:
        raise CommandError(str(exc)) from exc


def check_columns(frame, columns, path):
    missing = [c for c in columns if c not in frame.columns]
    if missing:
        raise CommandError(f"{path}: missing column(s) {missing}; available: {list(frame.columns)}")


# The --time value of fit and predict that takes the rows in file order (no time column).
NO_TIME = "none"


def check_time_column(frame, time, path, *, file_order):
    """One rule for every command: the time column ``time`` must be in the file, unless
    ``file_order`` commands are told ``--time none``; the error names both fixes."""
    if time == NO_TIME:
        if file_order:
            return
        raise CommandError(
            f"{path}: this command needs a time column (the smoothness of the estimate is a "
            "time derivative); name it with --time"
        )
    if time not in frame.columns:
        alternative = f", or pass --time {NO_TIME} to take the rows in file order" * file_order
        raise CommandError(
            f"{path}: missing the time column {time!r}; name yours with --time{alternative}. "
            f"Columns: {list(frame.columns)}"
        )


def in_time_order(frame, path, *, recording, time):
    """The rows of ``frame`` gathered by recording and sorted by ``time`` (None: file order).

    Raises a CommandError naming the file, the recording, the row and the time when an id or
    a time is missing, or a time is repeated within a recording.
    """
    times = None if time is None else frame[time]
    order = time_order(frame[recording], times)
    frame = frame.iloc[order].reset_index(drop=True)
    columns = {RECORDING: frame[recording]}
    if time is not None:
        columns[TIME] = frame[time]
    try:
        tidy_frame(columns, source=f"file {str(path)!r}", row=order)
    except ValueError as exc:
        message = str(exc).replace(f"column '{RECORDING}'", f"column {recording!r}")
        raise CommandError(message.replace(f"column '{TIME}'", f"column {time!r}")) from exc
    return frame


def load_model(path, *, return_training=False):
    """The model saved by ``skhmmgmr fit`` (:func:`skhmmgmr.portable.load`: a regressor or a
    torque pipeline), the portable JSON format only; with ``return_training``, also the
    file's facts about the training data (its sampling period)."""
    from ..portable import load

    path = Path(path)
    if not path.is_file():
        raise CommandError(f"model file not found: {path}")
    try:
        model, training = load(path, return_training=True)
    except Exception as exc:  # any failure is the file's: it is read as data, never run
        raise CommandError(
            f"cannot load the model file {path}: {exc}. Model files are the portable JSON "
            "written by 'skhmmgmr fit'; pickle and joblib files are never loaded (loading "
            "them can run code)"
        ) from exc
    if not hasattr(model, "feature_names_in_"):
        raise CommandError(
            f"{path}: the model was fitted without feature names; fit it with 'skhmmgmr fit' "
            "or on a DataFrame"
        )
    return (model, training) if return_training else model


def _holds(output, source):
    """Whether writing ``output`` would overwrite the file or folder ``source``."""
    output, source = Path(output).resolve(), Path(source).resolve()
    if output == source or output in source.parents:
        return True
    return output.exists() and source.exists() and os.path.samefile(output, source)


def check_output(path, *, overwrite, inputs=(), report=False):
    """Refuse, before the run, an output that cannot be written or must not be replaced.

    Parameters
    ----------
    path : str or path-like
        The ``--output`` of the command.
    overwrite : bool
        ``--overwrite``: replace an existing file (or a folder that is not a report).
    inputs : iterable of str or path-like
        Files and folders the command reads: never overwritten, even with ``overwrite``.
    report : bool, default=False
        Whether the output is a report folder, which replaces an earlier report freely.
    """
    path = Path(path)
    parent = path.parent
    if not parent.is_dir():
        problem = "does not exist" if not parent.exists() else "is not a folder"
        raise CommandError(f"--output {path}: the folder {parent} {problem}")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise CommandError(f"--output {path}: the folder {parent} is not writable")
    for source in inputs:
        if _holds(path, source):
            raise CommandError(
                f"--output {path} would overwrite the input {source}; choose another output "
                "(--overwrite never replaces an input)"
            )
    if report:
        try:
            check_replaceable(path, overwrite=overwrite)
        except (ValueError, OSError) as exc:
            raise CommandError(f"--output {exc}") from exc
    elif path.is_dir():
        raise CommandError(f"--output {path} is a folder; name a file")
    elif os.path.lexists(path) and not overwrite:
        raise CommandError(f"--output {path} exists; pass --overwrite to replace it")


def write_output(path, write):
    """Write ``path`` through ``write(partial_path)``, then swap the complete file in.

    The partial file is beside ``path`` and ends with its name, so that pandas infers the
    same compression; it is removed when the write fails or is interrupted.
    """
    path = Path(path)
    partial = path.with_name(f".partial-{os.getpid()}-{path.name}")
    try:
        write(partial)
        os.replace(partial, path)
    except OSError as exc:
        raise CommandError(f"cannot write {path}: {exc.strerror or exc}") from exc
    finally:
        partial.unlink(missing_ok=True)


def assign_splits(frame, args):
    """Train/validation/test by recording when the data has no usable split column."""
    recordings = frame[RECORDING].unique()
    if len(recordings) < 3:
        raise CommandError(
            f"{args.data}: {len(recordings)} recording(s); the framework needs at least 3 "
            "(training, validation and test)"
        )
    order = np.random.default_rng(args.seed).permutation(recordings)
    n_val = max(1, round(args.validation_fraction * len(order)))
    n_test = max(1, round(args.test_fraction * len(order)))
    if n_val + n_test >= len(order):
        raise CommandError("--validation-fraction + --test-fraction leave no training recording")
    split = {r: "validation" for r in order[:n_val]}
    split.update({r: "test" for r in order[n_val : n_val + n_test]})
    return frame[RECORDING].map(split).fillna("train")
