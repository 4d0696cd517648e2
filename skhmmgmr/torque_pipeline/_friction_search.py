"""The ``"auto"`` choice of the friction band and the velocity filter of ``SteeringFeatures``.

The friction band is the steering system's, and whether the velocity needs the filter depends
on its sensor: both differ from car to car. With ``"auto"`` (the default of
:func:`~skhmmgmr.make_torque_pipeline`) ``fit`` chooses them on the training recordings:
every candidate of :data:`FRICTION_CANDIDATES` and :data:`FILTER_CANDIDATES` is scored by the
held-out error of a least-squares fit of the target on the inputs and the derived inputs, the
recordings split in :data:`SEARCH_FOLDS` folds, and the candidate of least error is kept. A
linear fit ranks the candidates nearly as the regressor does (the friction input enters every
state's regression alike) at a small part of its cost: one pass over the rows per fold and
candidate, the fits coming from the folds' sums of products.
"""

import math

import numpy as np
import pandas as pd

AUTO = "auto"
#: The friction bands [rad/s] ``friction_velocity="auto"`` compares (a factor 2 apart, over the
#: bands of passenger cars' steering systems).
FRICTION_CANDIDATES = (0.025, 0.05, 0.1, 0.2, 0.4, 0.8)
#: The velocity filters [s] ``velocity_filter="auto"`` compares (``None``: no filter).
FILTER_CANDIDATES = (None, 0.02, 0.05)
#: Folds of the inner validation of the "auto" choices.
SEARCH_FOLDS = 3


def search_candidates(friction_velocity, velocity_filter, sampling_period):
    """The (friction band, velocity filter) pairs the inner validation compares: every
    candidate of an ``"auto"`` setting, the setting itself otherwise (no filter without the
    sampling period, which a filter needs)."""
    bands = FRICTION_CANDIDATES if friction_velocity == AUTO else (friction_velocity,)
    if velocity_filter != AUTO:
        filters = (velocity_filter,)
    elif sampling_period is None:
        filters = (None,)
    else:
        filters = FILTER_CANDIDATES
    return [(band, time_constant) for time_constant in filters for band in bands]


def friction_search(base, target, recordings, candidates, friction_of, settings):
    """The table of the ``"auto"`` choice: every candidate's validation RMSE.

    Parameters
    ----------
    base : ndarray of shape (n_samples, n_base)
        The inputs and the load inputs, rows in filter order.
    target : ndarray of shape (n_samples, n_outputs)
    recordings : Recordings
        The recordings of the rows, for the folds.
    candidates : list of (float, float or None)
        The (friction band, velocity filter) pairs (:func:`search_candidates`).
    friction_of : callable
        ``friction_of(band, time_constant)``: the friction input of a candidate.
    settings : str
        The settings searched, for the error when the rows are too few.

    Returns
    -------
    table : DataFrame
        ``friction_velocity``, ``velocity_filter``, ``validation_rmse`` and ``chosen`` (the
        first candidate of least error, in the order of ``candidates``).
    """
    folds = search_folds(recordings, len(base))
    columns = [friction_of(band, time_constant) for band, time_constant in candidates]
    rmse = validation_rmse(base, columns, target, folds, settings)
    best = int(np.argmin(rmse))  # the first of equal ones: the order of the candidates
    return pd.DataFrame(
        {
            "friction_velocity": [float(band) for band, _ in candidates],
            "velocity_filter": pd.Series([tc for _, tc in candidates], dtype=object),
            "validation_rmse": rmse,
            "chosen": np.arange(len(candidates)) == best,
        }
    )


def search_folds(recordings, n_samples):
    """The fold of every row for the inner validation: whole recordings, in turn, when there
    are at least :data:`SEARCH_FOLDS`; else every recording cut in that many consecutive
    blocks."""
    folds = np.empty(n_samples, dtype=np.intp)
    spans = list(zip(recordings.starts, recordings.stops, strict=True))
    for number, (start, stop) in enumerate(spans):
        if len(spans) >= SEARCH_FOLDS:
            folds[start:stop] = number % SEARCH_FOLDS
        else:
            folds[start:stop] = np.arange(stop - start) * SEARCH_FOLDS // (stop - start)
    return folds


def validation_rmse(base, candidates, target, folds, settings):
    """Held-out RMSE of a least-squares fit of ``target`` on ``base`` and each candidate
    column, every fold left out in turn (the rows where any of them is missing left out).

    One pass over the rows per fold and candidate: the fits come from the folds' sums of
    products, the training sum being the total less the held-out fold's.
    """
    finite = np.isfinite(base).all(axis=1) & np.isfinite(target).all(axis=1)
    for column in candidates:
        finite &= np.isfinite(column)
    base, target, folds = base[finite], target[finite], folds[finite]
    used = [fold for fold in range(SEARCH_FOLDS) if np.any(folds == fold)]
    if len(used) < 2 or len(base) <= base.shape[1] + 2:
        raise ValueError(
            f"{settings}: the 'auto' choice needs rows with every input and the target "
            f"observed in at least 2 parts of the data; got n_samples={len(base)} such rows. "
            "Give more recordings, or fixed values."
        )
    scale = base.std(axis=0)
    scale[scale == 0] = 1.0
    base = (base - base.mean(axis=0)) / scale
    base = np.column_stack([np.ones(len(base)), base])
    n_base, n_outputs = base.shape[1], target.shape[1]
    # every fold's rows, sums of products and base and target columns, once for all candidates
    parts = {}
    for fold in used:
        rows = folds == fold
        parts[fold] = (rows, base[rows], target[rows])
    sums = {
        fold: _products(fold_base, fold_target)
        for fold, (_, fold_base, fold_target) in parts.items()
    }
    rmse = []
    for column in candidates:
        column = column[finite]
        held_out = {
            fold: _with_column(sums[fold], fold_base, fold_target, column[rows])
            for fold, (rows, fold_base, fold_target) in parts.items()
        }
        total = sum(held_out.values())
        squared = 0.0
        for fold in used:
            trained = total - held_out[fold]
            squared += _held_out_squares(trained, held_out[fold], n_base + 1)
        rmse.append(math.sqrt(max(squared, 0.0) / (len(base) * n_outputs)))
    return np.asarray(rmse)


def _products(base, target):
    """Sums of products of the columns ``[base, target]`` of one fold."""
    joined = np.column_stack([base, target])
    return joined.T @ joined


def _with_column(products, base, target, column):
    """The sums of products of ``[base, column, target]`` from those of ``[base, target]``."""
    n_base = base.shape[1]
    cross = np.concatenate([base.T @ column, [column @ column], target.T @ column])
    size = products.shape[0] + 1
    out = np.empty((size, size))
    order = [*range(n_base), *range(n_base + 1, size)]  # where [base, target] go
    out[np.ix_(order, order)] = products
    out[n_base, :] = out[:, n_base] = cross
    return out


def _held_out_squares(trained, held_out, n_inputs):
    """Sum of squared residuals on the held-out fold of the least-squares fit on the trained
    sums (inputs first, then the targets), a tiny ridge keeping it solvable."""
    gram, cross = trained[:n_inputs, :n_inputs], trained[:n_inputs, n_inputs:]
    ridge = 1e-9 * np.trace(gram) / n_inputs
    coef = np.linalg.solve(gram + ridge * np.eye(n_inputs), cross)
    inputs, outputs = held_out[:n_inputs, :n_inputs], held_out[:n_inputs, n_inputs:]
    squares = held_out[n_inputs:, n_inputs:]
    return float(np.trace(squares - 2.0 * coef.T @ outputs + coef.T @ inputs @ coef))
