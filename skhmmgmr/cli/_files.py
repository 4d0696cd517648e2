"""Files of the command line: inputs read in the package's one row order, outputs guarded.

Inputs: a CSV or Parquet table, read by the loaders' reader (recording ids as text, every error
naming the file); its rows put in the order of :func:`~skhmmgmr.datasets.load_recordings`
(recordings contiguous in order of first appearance, rows sorted by time, a repeated time
refused); and the model file (a regressor or a torque pipeline), read only as the portable JSON
format, never unpickled.

Outputs: checked before the run by the package's one rule for output files
(:func:`~skhmmgmr._core._files.check_output_paths`), so that a long run never ends in an error
it could have reported at once (the folder exists and is writable, a user's file only with
``--overwrite``), with two rules of the command line's own: an input is never overwritten,
and a report folder replaces an earlier report freely. Every error names the option the path
came from. Files are then written through a temporary file created exclusively beside the
target and swapped in when complete
(:func:`~skhmmgmr._core._files.write_atomically`), so that an interrupted run leaves the
previous file as it was and a file or link planted beside the target is never followed.

Splits: data without a usable split column are split by recording at random
(:func:`assign_splits`).
"""

import os
from pathlib import Path

import numpy as np
import pandas as pd

from .._core._files import check_output_paths, write_atomically
from .._core._schema import DRIVER, RECORDING, SPLIT, TIME
from ..datasets._frame import tidy_frame, time_order
from ..datasets._recordings import read_table
from ._options import NO_TIME, log
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


def ordered_data(args):
    """The data of ``fit``/``predict``, rows gathered by recording and sorted by time (in file
    order with ``--time none``)."""
    frame = read_data(args.data, args.recording)
    check_columns(frame, [args.recording], args.data)
    check_time_column(frame, args.time, args.data, file_order=True)
    time = None if args.time == NO_TIME else args.time
    if time is None:
        log(args, f"--time {NO_TIME}: the rows of {args.data} are taken in file order")
    return in_time_order(frame, args.data, recording=args.recording, time=time)


def model_inputs(frame, features, args):
    """The feature columns, indexed by the time column when there is one: a velocity filter
    checks its sampling period against it in every recording."""
    X = frame[features]
    if args.time == NO_TIME:
        return X
    return X.set_axis(pd.Index(frame[args.time].to_numpy(dtype=float), name=TIME))


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


def check_output(paths, *, option, overwrite, inputs=(), report=False, create_folders=False):
    """Refuse, before the run, outputs that cannot be written or must not be replaced.

    Parameters
    ----------
    paths : path-like or sequence of path-like
        The files (or the report folder) the option names.
    option : str
        The option the paths come from (``--output``, ``--metrics``...), named in every
        error.
    overwrite : bool
        ``--overwrite``: replace an existing file (or a folder that is not a report).
    inputs : iterable of str or path-like
        Files and folders the command reads: never overwritten, even with ``overwrite``.
    report : bool, default=False
        Whether the output is a report folder, which replaces an earlier report freely.
    create_folders : bool, default=False
        Whether a missing folder is made (else refused).
    """
    paths = [Path(paths)] if isinstance(paths, str | os.PathLike) else list(map(Path, paths))
    for path in paths:
        for source in inputs:
            if _holds(path, source):
                raise CommandError(
                    f"{option} {path} would overwrite the input {source}; choose another "
                    "output (--overwrite never replaces an input)"
                )
    try:
        if report:
            (path,) = paths
            if not path.is_dir():  # the folder it goes in is checked as a file's
                check_output_paths(paths, overwrite=True, option=option, create_folders=False)
            elif not os.access(path.parent, os.W_OK | os.X_OK):
                raise PermissionError(f"{path}: the folder {path.parent} is not writable")
            check_replaceable(path, overwrite=overwrite)
        else:
            check_output_paths(
                paths, overwrite=overwrite, option=option, create_folders=create_folders
            )
    except (ValueError, OSError) as exc:
        message = str(exc)
        raise CommandError(
            message if message.startswith(option) else f"{option} {message}"
        ) from exc


def write_output(path, write):
    """Write ``path`` through ``write(temporary_path)``
    (:func:`~skhmmgmr._core._files.write_atomically`: a temporary file created exclusively
    beside ``path``, ending with its name so that pandas infers the same format and
    compression, swapped in when complete and removed when the write fails)."""
    try:
        write_atomically(path, write=write)
    except OSError as exc:
        raise CommandError(f"cannot write {path}: {exc.strerror or exc}") from exc


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
