"""The ``"auto"`` choice of the friction inputs, the hysteresis inputs and the velocity filter
of ``SteeringFeatures``.

Friction differs from one steering system to the next: the band of steering-wheel velocities
over which it changes sign spans two orders of magnitude among cars (a few thousandths to
tenths of a radian per second), and how finely the velocity resolves that band depends on the
sensor and the sampling rate. With ``friction_velocity="auto"`` (the default of
:func:`~skhmmgmr.make_torque_pipeline`) ``fit`` reads the friction inputs from the training
recordings:

- **the ladder** (:func:`velocity_ladder`): widths a factor 2 apart on :data:`WIDTH_GRID`
  (``0.1 * 2**k`` rad/s), from the narrowest the velocity resolves (a band whose transition,
  ``|v| < 2 w``, holds at least the :data:`LADDER_QUANTILES` low share of the rows with a
  non-zero velocity: below the velocity's noise and quantisation scale every narrower band is
  the same sign of the noise) up to the widest the data needs (the high quantile of ``|v|``:
  a wider band is nearly linear over almost every row, and the velocity is an input already),
  read from the velocity the inputs use: each velocity filter's own, a filtered velocity
  being less noisy and resolving narrower bands;
- **the ladder of the hysteresis** (``friction_angle="auto"``, :func:`angle_ladder`): plays
  of half-widths a factor 2 apart on :data:`RADIUS_GRID` (``0.001 * 2**k`` rad), from half the
  angle's resolution (the low :data:`ANGLE_QUANTILES` quantile of its non-zero steps: a
  narrower play turns over at every step) up to the high quantile of the angle's distance
  from its median (a wider play is nearly the angle itself);
- **the candidates**: no friction input, and every window of consecutive widths of the ladder
  (a basis ``tanh(v / w_j)``, whose combination each state's regression fits: one width is
  one band), each with no hysteresis input or every window of consecutive half-widths of its
  ladder, with each velocity filter of :data:`FILTER_CANDIDATES`, the plays reading the
  angle or, with ``angle_lead="auto"``, the angle led on the velocity by each lead of
  :data:`ANGLE_LEADS` (an angle sensor's steps may be coarser than the plays: the velocity
  places the angle between them), and with ``slow_velocity_filter="auto"`` each basis also
  on the velocity through each slow filter of :data:`SLOW_FILTER_CANDIDATES` (a column
  whose friction lags the wheel), or not;
- **the score**: the held-out error of a least-squares fit of the target on the inputs, the
  load inputs and the candidate's friction and hysteresis inputs, the recordings split in
  :data:`SEARCH_FOLDS` folds;
- **the rule**: the fewest friction and hysteresis inputs whose error is within
  :data:`PARSIMONY` of the least; of those, the least error. A car without friction keeps
  none, a car whose friction one band describes keeps one, a column whose friction sticks
  keeps plays.

A linear fit ranks the candidates nearly as the regressor does (the friction inputs enter
every state's regression alike) at a small part of its cost: one pass over the rows per
velocity filter and fold, every candidate's fit coming from the fold's sums of products.
"""

import math

import numpy as np
import pandas as pd

from ._derived_inputs import (
    filtered_velocity,
    friction_inputs,
    friction_widths,
    led_angle,
    load_inputs,
    recording_hysteresis,
)

AUTO = "auto"
#: The widths [rad/s] a ladder of friction bands takes, a factor 2 apart: ``0.1 * 2**k``,
#: from 0.1 / 1024 (below any velocity sensor's resolution) to 1.6 rad/s.
WIDTH_GRID = tuple(0.1 * 2.0**k for k in range(-10, 5))
#: The shares of the rows (with a non-zero velocity) that set the ladder's ends: the
#: narrowest band's transition ``|v| < 2 w`` holds at least the first, the widest band is at
#: most the second quantile of ``|v|``.
LADDER_QUANTILES = (0.05, 0.9)
#: The half-widths [rad] a ladder of plays takes, a factor 2 apart: ``0.001 * 2**k``, from
#: 1/16 to 64 mrad.
RADIUS_GRID = tuple(0.001 * 2.0**k for k in range(-4, 7))
#: The quantiles that set the ends of the ladder of plays: of the angle's non-zero steps
#: (twice the narrowest at least), of its distance from its median (the widest at most).
ANGLE_QUANTILES = (0.05, 0.25)
#: The velocity filters [s] ``velocity_filter="auto"`` compares (``None``: no filter).
FILTER_CANDIDATES = (None, 0.02, 0.05)
#: The slow velocity filters [s] ``slow_velocity_filter="auto"`` compares (``None``: no
#: friction inputs of a slow velocity).
SLOW_FILTER_CANDIDATES = (None, 0.1, 0.2)
#: The leads [s] ``angle_lead="auto"`` compares (``None``: the plays read the angle itself).
ANGLE_LEADS = (None, 0.02, 0.05)
#: Folds of the inner validation of the "auto" choices.
SEARCH_FOLDS = 3
#: The relative held-out error within which fewer friction and hysteresis inputs are
#: preferred.
PARSIMONY = 0.005


def search_filters(velocity_filter, sampling_period, candidates=FILTER_CANDIDATES):
    """The velocity filters the inner validation compares: every one of ``candidates`` for
    ``"auto"`` (none without the sampling period, which a filter needs), the setting itself
    otherwise."""
    if velocity_filter != AUTO:
        return (velocity_filter,)
    if sampling_period is None:
        return (None,)
    return candidates


def search_leads(angle_lead):
    """The angle leads the inner validation compares: every one of ``"auto"``, the setting
    itself otherwise (``None`` without plays)."""
    return ANGLE_LEADS if angle_lead == AUTO else (angle_lead,)


def velocity_ladder(velocity):
    """The widths of :data:`WIDTH_GRID` the velocity resolves and the data needs (see the
    module's docstring); empty when no row has a non-zero finite velocity."""
    size = np.abs(velocity[np.isfinite(velocity)])
    size = size[size > 0]
    if not size.size:
        return ()
    low, high = np.quantile(size, LADDER_QUANTILES)
    ladder = tuple(w for w in WIDTH_GRID if 2.0 * w >= low and w <= high)
    if not ladder:  # a velocity of one size: the band at its scale
        ladder = (min(WIDTH_GRID, key=lambda w: abs(math.log(w / high))),)
    return ladder


def angle_ladder(angle, recordings):
    """The half-widths of :data:`RADIUS_GRID` the angle resolves and the data needs (see the
    module's docstring); empty when the angle never moves."""
    steps = []
    for start, stop in zip(recordings.starts, recordings.stops, strict=True):
        steps.append(np.abs(np.diff(angle[start:stop])))
    steps = np.concatenate(steps) if steps else np.empty(0)
    steps = steps[np.isfinite(steps) & (steps > 0)]
    observed = angle[np.isfinite(angle)]
    if not steps.size:
        return ()
    low = np.quantile(steps, ANGLE_QUANTILES[0])
    high = np.quantile(np.abs(observed - np.median(observed)), ANGLE_QUANTILES[1])
    ladder = tuple(r for r in RADIUS_GRID if 2.0 * r >= low and r <= high)
    if not ladder:  # an angle that moves less than its steps: the play at its resolution
        ladder = (min(RADIUS_GRID, key=lambda r: abs(math.log(2.0 * r / low))),)
    return ladder


def basis_windows(ladder):
    """No friction input (``None``), then every window of consecutive widths of ``ladder``,
    fewest first: ``(friction_velocity, indices of its widths in the ladder)``."""
    windows = [(None, ())]
    for size in range(1, len(ladder) + 1):
        for start in range(len(ladder) - size + 1):
            indices = tuple(range(start, start + size))
            windows.append((tuple(ladder[i] for i in indices), indices))
    return windows


def friction_search(base, target, recordings, searched, settings):
    """The table of the ``"auto"`` choice: every candidate's validation RMSE, and the chosen.

    Parameters
    ----------
    base : ndarray of shape (n_samples, n_base)
        The inputs and the load inputs, rows in filter order.
    target : ndarray of shape (n_samples, n_outputs)
    recordings : Recordings
        The recordings of the rows, for the folds.
    searched : list of (float or None, list of ndarray, list of (dict, tuple of int))
        Per velocity filter and angle lead: the filter's time constant, the friction and
        hysteresis columns they give (one per width) and their candidates, each the settings
        it stands for (``friction_velocity``, ``friction_angle``, ``angle_lead``) and the
        indices of its columns (``settings`` holds ``slow_velocity_filter`` too).
    settings : str
        The settings searched, for the error when the rows are too few.

    Returns
    -------
    table : DataFrame
        The settings of every candidate (``friction_velocity``: a width, a tuple of widths or
        None; ``friction_angle``: a tuple of half-widths or None; ``angle_lead``;
        ``slow_velocity_filter``),
        ``velocity_filter``,
        ``n_friction_inputs`` (friction and hysteresis inputs), ``validation_rmse`` and
        ``chosen`` (by the rule of the module's docstring; the first of equal ones in the
        order of ``searched``).
    """
    folds = search_folds(recordings, len(base))
    finite = np.isfinite(base).all(axis=1) & np.isfinite(target).all(axis=1)
    for _, columns, _ in searched:
        for column in columns:
            finite &= np.isfinite(column)
    base, target, folds = _standardized(base[finite]), target[finite], folds[finite]
    used = [fold for fold in range(SEARCH_FOLDS) if np.any(folds == fold)]
    if len(used) < 2 or len(base) <= base.shape[1] + 2:
        raise ValueError(
            f"{settings}: the 'auto' choice needs rows with every input and the target "
            f"observed in at least 2 parts of the data; got n_samples={len(base)} such rows. "
            "Give more recordings, or fixed values."
        )
    rows = []
    for time_constant, columns, candidates in searched:
        joined = np.column_stack([base, *(column[finite] for column in columns), target])
        products = {fold: _products(joined[folds == fold]) for fold in used}
        total = sum(products.values())
        n_base, n_outputs = base.shape[1], target.shape[1]
        outputs = np.arange(joined.shape[1] - n_outputs, joined.shape[1])
        for settings_of, indices in candidates:
            inputs = np.array([*range(n_base), *(n_base + i for i in indices)], dtype=np.intp)
            squared = sum(
                _held_out_squares(total - products[fold], products[fold], inputs, outputs)
                for fold in used
            )
            rmse = math.sqrt(max(squared, 0.0) / (len(base) * n_outputs))
            rows.append((settings_of, time_constant, len(indices), rmse))
    table = pd.DataFrame(
        {name: pd.Series([row[0][name] for row in rows], dtype=object) for name in rows[0][0]}
    )
    table["velocity_filter"] = pd.Series([row[1] for row in rows], dtype=object)
    table["n_friction_inputs"] = [row[2] for row in rows]
    table["validation_rmse"] = [row[3] for row in rows]
    table["chosen"] = np.arange(len(table)) == choose(table)
    return table


def choose(table):
    """The row of the chosen candidate: the fewest friction inputs within :data:`PARSIMONY`
    of the least validation RMSE, then the least RMSE, then the first."""
    rmse = table["validation_rmse"].to_numpy()
    near = np.flatnonzero(rmse <= rmse.min() * (1.0 + PARSIMONY))
    fewest = table["n_friction_inputs"].to_numpy()[near].min()
    near = near[table["n_friction_inputs"].to_numpy()[near] == fewest]
    return int(near[np.argmin(rmse[near])])  # argmin: the first of equal ones


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


def _standardized(base):
    """A column of ones, then the columns of ``base`` centred and scaled (a constant one
    only centred)."""
    scale = base.std(axis=0)
    scale[scale == 0] = 1.0
    return np.column_stack([np.ones(len(base)), (base - base.mean(axis=0)) / scale])


def _products(joined):
    """Sums of products of the columns of one fold."""
    return joined.T @ joined


def _held_out_squares(trained, held_out, inputs, outputs):
    """Sum of squared residuals on the held-out fold of the least-squares fit of the columns
    ``outputs`` on the columns ``inputs``, from the sums of products of the training rows and
    of the held-out ones, a tiny ridge keeping it solvable. ``inputs`` and ``outputs``:
    arrays of column indices."""
    rows, output_rows = inputs[:, None], outputs[:, None]
    gram, cross = trained[rows, inputs], trained[rows, outputs]
    ridge = 1e-9 * np.trace(gram) / len(inputs)
    coef = np.linalg.solve(gram + ridge * np.eye(len(inputs)), cross)
    products, targets = held_out[rows, inputs], held_out[rows, outputs]
    squares = held_out[output_rows, outputs]
    return float(np.trace(squares - 2.0 * coef.T @ targets + coef.T @ products @ coef))


def candidate_table(step, layout, values, y, positions, settings):
    """The table of the ``"auto"`` choice of ``step`` (a ``SteeringFeatures`` in its ``fit``)
    on rows in filter order: every candidate's validation RMSE (:func:`friction_search`), the
    ladder of widths of ``"auto"`` read from each filter's velocity, that of the plays from
    the angle. ``positions``: the source columns' positions in ``values``; ``settings``: the
    settings searched, as the errors name them."""
    target = np.asarray(y, dtype=float).reshape(len(values), -1)
    loads = load_inputs(values, positions, step.load_columns, step.powers)
    recordings = layout.recordings(len(values))
    if step.friction_angle_ is None:
        radii, plays = (), [(None, ())]
    else:
        angle = values[:, positions[step.angle_column]]
        if step.friction_angle_ == AUTO:
            radii = angle_ladder(angle, recordings)
            plays = basis_windows(radii)
        else:
            radii = step.friction_angle_
            plays = [(radii, tuple(range(len(radii))))]
    leads = search_leads(step.angle_lead_) if radii else (None,)
    hysteresis = {None: []}
    for lead in leads if radii else ():
        led = angle
        if lead is not None:
            led = led_angle(angle, values[:, positions[step.friction_column]], lead)
        hysteresis[lead] = list(recording_hysteresis(led, layout, radii).values())
    velocity, slow_filters = None, (None,)
    if step.friction_velocity is not None:
        velocity = values[:, positions[step.friction_column]]
        slow_filters = search_filters(
            step.slow_velocity_filter_, step.sampling_period_, SLOW_FILTER_CANDIDATES
        )
    # the slow velocities, filtered once for every velocity filter's ladder
    slow_velocities = {
        slow: filtered_velocity(velocity, layout, step.sampling_period_, slow)
        for slow in slow_filters
        if slow is not None
    }
    searched = []
    for time_constant in search_filters(step.velocity_filter_, step.sampling_period_):
        if velocity is None:
            widths, bands = (), [(None, ())]
        else:
            filtered = velocity
            if time_constant is not None:
                filtered = filtered_velocity(velocity, layout, step.sampling_period_, time_constant)
            if step.friction_velocity_ == AUTO:
                widths = velocity_ladder(filtered)
                bands = basis_windows(widths)
            else:
                widths = friction_widths(step.friction_velocity_)
                bands = [(step.friction_velocity_, tuple(range(len(widths))))]
        columns = list(friction_inputs(filtered, widths).values()) if widths else []
        # the friction inputs of every slow velocity, on the same ladder (offset: their first)
        offsets = {None: None}
        for slow, slowed in slow_velocities.items():
            offsets[slow] = len(columns)
            columns += list(friction_inputs(slowed, widths).values()) if widths else []
        for lead in leads:
            # without plays a lead changes nothing: those candidates come with the first
            candidates = [
                (
                    {
                        "friction_velocity": band,
                        "friction_angle": play,
                        "angle_lead": None if play is None else lead,
                        "slow_velocity_filter": slow,
                    },
                    (
                        *band_columns,
                        *(() if slow is None else (offsets[slow] + i for i in band_columns)),
                        *(len(columns) + i for i in play_columns),
                    ),
                )
                for band, band_columns in bands
                for slow in (slow_filters if band is not None else (None,))
                for play, play_columns in plays
                if play is not None or lead == leads[0]
            ]
            searched.append((time_constant, [*columns, *hysteresis[lead]], candidates))
    return friction_search(
        np.column_stack([values, *loads.values()]),
        target,
        layout.recordings(len(values)),
        searched,
        settings,
    )
