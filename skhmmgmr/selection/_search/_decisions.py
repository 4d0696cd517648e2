"""Which screened scores the relevance's decisions can read: the fast search's
decision-relevant confirmation.

The feature relevance counts, for every trade-off, the features of every recording's best
subset (the exhaustive wrapper) or of every recording's final forward subset; the candidate
subsets keep the features whose count reaches a threshold (Strict, Mild, Liberal:
:data:`THESIS_SHARES` of the recordings). Those threshold decisions are what the framework
reads, not the per-recording winners themselves.

The argument. Let a screened model's terms (``|100 - accuracy|`` and the smoothness of every
validation recording) be within ``tolerance`` (relative) of those of the full search's fit of
the same model, and a model fitted in full be exact. Every score then lies in an interval
(:func:`normalised_bounds`: the D.5 normalisation divides by sums over all models, screened
ones included, so a model fitted in full has an interval too), and each unit (a (trade-off,
recording) pair, a forward path) ends, in the full search, with one of its *possible*
outcomes (the subsets whose interval reaches below the upper end of every other's). For a
feature ``f`` and a threshold ``t`` of one trade-off, ``low`` counts the units where every
possible outcome holds ``f`` and ``high`` those where some does: the full search's count lies
in ``[low, high]``, so if ``t <= low`` or ``high < t`` the decision ``count >= t`` is the full
search's whatever the unconfirmed units end with. Only an undecided ``(f, t)`` sends units to
be confirmed (their screened possible outcomes fitted in full), and only as many as can
settle it (:func:`units_to_confirm`); the caller repeats until none is sent. Every decision
the bound then settles is the full search's; a decision can stay open when the possible
outcomes of a unit are all fitted in full and still within the drift of the sums
(:func:`open_decisions` names them): only fitting the screened models of the sums settles it.
The guarantee is exactly as good as the bound: a screened term further than ``tolerance``
from its full fit can flip a settled decision (the user guide gives the measured errors).
"""

import math

import numpy as np
import pandas as pd

#: The candidate strategies' shares of the recordings (``None``: counted at least once), as
#: :func:`~skhmmgmr.selection.candidate_subsets` takes them by default.
THESIS_SHARES = {"Strict": 0.66, "Mild": 0.33, "Liberal": None}


def count_thresholds(n_units, shares=tuple(THESIS_SHARES.values())):
    """The counts a feature must reach, one per share (as ``candidate_subsets`` sets them)."""
    return sorted({1.0 if share is None else max(share * n_units, 1.0) for share in shares})


def score_bounds(values, exact, tolerance):
    """Lower and upper ends of the performance scores ``values`` (positive): exact where
    ``exact``, else within ``tolerance`` (relative)."""
    values = np.asarray(values, dtype=float)
    error = np.where(np.asarray(exact, dtype=bool), 0.0, tolerance) * np.abs(values)
    return values - error, values + error


def possible_winners(values, exact, tolerance):
    """Mask of the options that can have the lowest score: whose lower end is not above
    the lowest upper end."""
    low, high = score_bounds(values, exact, tolerance)
    return low <= high.min()


def units_to_confirm(always, ever, point, thresholds, margin=None):
    """The units to confirm so that every undecided threshold decision can be settled.

    Parameters
    ----------
    always, ever, point : ndarray of bool, shape (n_units, n_features)
        Per unit and feature: every possible outcome holds the feature; some does; the
        screened outcome (the point estimate) does.
    thresholds : list of float
        The counts decided (``count >= threshold``).
    margin : ndarray of shape (n_units, n_features), default=None
        How sure the screened outcome is (larger: surer); the surest units are confirmed
        first. ``None``: in unit order.

    Returns
    -------
    units : set of int
        For every undecided ``(feature, threshold)``: the fewest units that, should the
        screened outcomes hold, settle it on the side of the screened count (that many
        units whose possible outcomes disagree on the feature, agreeing with the screened
        count); none when every decision is settled.
    """
    always, ever, point = (np.asarray(a, dtype=bool) for a in (always, ever, point))
    low, high, count = always.sum(axis=0), ever.sum(axis=0), point.sum(axis=0)
    if margin is None:
        margin = np.zeros(always.shape)
    chosen = set()
    for feature in range(always.shape[1]):
        swing = always[:, feature] != ever[:, feature]
        for threshold in thresholds:
            if not low[feature] < threshold <= high[feature]:
                continue  # decided by the bounds
            reached = math.ceil(threshold)
            if count[feature] >= threshold:  # show count >= threshold
                pool, needed = swing & point[:, feature], reached - low[feature]
            else:  # show count < threshold
                pool, needed = swing & ~point[:, feature], high[feature] - reached + 1
            # (the screened count holds, so the pool has at least ``needed`` units)
            units = np.flatnonzero(pool)
            surest = units[np.argsort(-margin[units, feature], kind="stable")]
            chosen.update(int(u) for u in surest[:needed])
    return chosen


def normalised_bounds(scores, tolerance):
    """Lower and upper ends of D.5-normalised performance scores (of
    :func:`~._score_tables.rescore_table`) when a screened model's terms (``|100 -
    accuracy|`` and the smoothness) are within ``tolerance`` (relative) of its full fit's.

    A term is normalised by its sum over the models of its recording, which holds the
    screened models' terms too: the sum is within ``tolerance`` times the screened models'
    share of it, so a model fitted in full has bounds as well, narrowing as more models are
    fitted in full.
    """
    flags = scores["screened"].to_numpy(dtype=bool)
    own = np.where(flags, tolerance, 0.0)
    bounds = []
    for sign in (-1.0, 1.0):
        total = np.zeros(len(scores))
        for term, weight in (
            ("accuracy_term", "accuracy_weight"),
            ("smoothness_term", "smoothness_weight"),
        ):
            values = scores[term].to_numpy(dtype=float)
            keys = [scores["trade_off"], scores["recording"]]
            share = pd.Series(np.where(flags, values, 0.0), index=scores.index)
            share = share.groupby(keys, sort=False).transform("sum").to_numpy()
            total_share = pd.Series(values, index=scores.index).groupby(keys, sort=False)
            total_share = total_share.transform("sum").to_numpy()
            drift = tolerance * np.divide(
                share, total_share, out=np.zeros(len(scores)), where=total_share > 0
            )
            weights = scores[weight].to_numpy(dtype=float)
            total += weights * values * (1.0 + sign * own) / (1.0 - sign * drift)
        bounds.append(total)
    return bounds[0], bounds[1]


def relevance_to_confirm(scores, key, members, tolerance, thresholds):
    """The screened models to fit in full so that the relevance's threshold decisions of
    every trade-off are settled (the exhaustive wrapper: every recording's best subset).

    Parameters
    ----------
    scores : pandas.DataFrame
        Performance scores (:func:`~._score_tables.rescore_table`, with its terms and
        weights) and ``screened``, with ``key``.
    key : str
        The column naming the model.
    members : callable
        ``members(model)``: the features (any hashable labels) of a model's subset.
    tolerance : float
        The bound of a screened model's terms' relative error (:func:`normalised_bounds`).
    thresholds : list of float
        As :func:`units_to_confirm` takes them.

    Returns
    -------
    models : set
        Screened models among the possible winners of the units to confirm. A unit whose
        possible winners are all fitted in full and still more than one (the sums of the
        screened models can order them either way) asks for none: the caller's loop ends
        with that decision open (:func:`open_decisions` names them).
    """
    possible, features = _possible(scores, key, tolerance, members)
    chosen = set()
    for _, units, always, ever, point, margin in _units(possible, key, members, features):
        for u in units_to_confirm(always, ever, point, thresholds, margin):
            unit = units[u][1]
            chosen.update(unit.loc[unit["screened"], key])
    return chosen


def open_decisions(scores, key, members, tolerance, thresholds):
    """The ``(trade-off, feature, threshold)`` the bound leaves open (as
    :func:`relevance_to_confirm` reads them)."""
    possible, features = _possible(scores, key, tolerance, members)
    found = []
    for label, _, always, ever, _, _ in _units(possible, key, members, features):
        low, high = always.sum(axis=0), ever.sum(axis=0)
        for j, feature in enumerate(features):
            found += [(label, feature, t) for t in thresholds if low[j] < t <= high[j]]
    return found


def _possible(scores, key, tolerance, members):
    """The rows of the possible winners of every (trade-off, recording), and the features."""
    low, high = normalised_bounds(scores, tolerance)
    pairs = [scores["trade_off"], scores["recording"]]
    lowest_high = pd.Series(high, index=scores.index).groupby(pairs, sort=False).transform("min")
    possible = scores[low <= lowest_high.to_numpy()]
    features = list(dict.fromkeys(f for model in possible[key].unique() for f in members(model)))
    return possible, features


def _units(possible, key, members, features):
    """Per trade-off: its units (recordings) and their ``always``, ``ever``, ``point`` and
    ``margin`` arrays (:func:`units_to_confirm`)."""
    column = {f: j for j, f in enumerate(features)}
    for label, block in possible.groupby("trade_off", sort=False):
        units = list(block.groupby("recording", sort=False))
        shape = (len(units), len(features))
        always, ever = np.ones(shape, dtype=bool), np.zeros(shape, dtype=bool)
        point, margin = np.zeros(shape, dtype=bool), np.zeros(shape)
        for u, (_, unit) in enumerate(units):
            held = np.zeros((len(unit), len(features)), dtype=bool)
            for row, model in enumerate(unit[key]):
                held[row, [column[f] for f in members(model)]] = True
            values = unit["performance_score"].to_numpy()
            always[u], ever[u] = held.all(axis=0), held.any(axis=0)
            point[u] = held[np.argmin(values)]
            for j in np.flatnonzero(always[u] != ever[u]):
                with_f, without = values[held[:, j]].min(), values[~held[:, j]].min()
                margin[u, j] = abs(with_f - without) / min(with_f, without)
        yield label, units, always, ever, point, margin
