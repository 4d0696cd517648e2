"""How strongly ``adapt`` moves a fitted model when ``relevance`` or ``parameters`` is "auto".

The adaptation recordings themselves say how far to move. Every recording is cut in time into
:data:`N_FOLDS` blocks of (nearly) equal length; fold ``i`` adapts the fitted model to all but
the ``i``-th block of every recording (each remaining block a recording of its own) and
estimates the outputs of the held-out blocks (each a recording, the filter restarting there).
The candidates go from "do not adapt" (``relevance=inf``) down the relevance grid
:data:`RELEVANCE_CANDIDATES`, over the parameter sets :data:`PARAMETER_CANDIDATES`, to a fresh
fit of the estimator on the recordings alone (``relevance=0``: no prior, every parameter new).
Every held-out block is cut into :data:`N_CHUNKS` chunks, and a candidate's score is the mean
over the chunks of the root mean squared error of its estimate in the chunk (in the fitted
model's standardised output units; rows whose target is missing do not count).

The choice starts with the one-standard-error rule of cross-validation (Hastie, Tibshirani
and Friedman, *The Elements of Statistical Learning*, 7.10) among the candidates that keep the
fitted model as a prior, towards it: the first, in the order "do not adapt", then relevance
from the largest to the smallest, whose score is at most the best of them plus
:data:`SE_FACTOR` standard errors of it (the spread of that candidate's chunk errors over the
square root of their number). A gain that the held-out chunks cannot tell from chance does not
move the model: the data of the fitted model's own drivers keep it as it is, while a driver
far from it moves it as far as the held-out rows support.

The fresh fit keeps nothing of the fitted model, and its time blocks share the roads of the
blocks it was fitted on: it replaces that choice only on clear evidence. It must be ahead of
the choice by :data:`FRESH_FIT_FACTOR` standard errors of their paired chunk differences
(which leave out how hard each chunk is, so that a steady lead counts), and then hold on
:func:`recording_folds`, which hold out every recording in turn (a road the fit has not seen):
there the choice must not be ahead of it by more than :data:`RECORDINGS_FACTOR` standard
errors of their differences. With a single recording there is none to hold out, and the fresh
fit's score on the time blocks must instead be lower than the choice's by the fraction
:data:`SINGLE_RECORDING_MARGIN`. Then the chosen candidate adapts to (or is fitted on) all the rows.

The constants were chosen on ``benchmarks/bench_adapt_defaults.py`` (simulated drivers held
out of a generic model in four cars, 1 to 5 minutes of adaptation data, data seeds 0-2, every
candidate's held-out errors kept so that rules compare without refitting) and checked on
seeds 3 and 4: eight folds rather than two to five, whose adaptations see too few rows to
judge the weak priors and the fresh fit; the chunks' root mean squared errors rather than
their squared errors, whose few large values make the standard error wide; two standard
errors of the best score for the adapted candidates. With the fresh fit as the last candidate
of that rule (the first form of "auto") it was chosen for a driver whose two minutes it
fitted well and the test roads did not confirm (0.34 point below the generic model), and
passed over for far drivers at 5 minutes (0.39 point behind a fresh fit on average). Its
paired test alone, at half a standard error, let through three cases of 2 minutes down to 1.9
points below the generic model; the held-out recordings reject them (allowing the fresh fit
to trail there by 1.5 standard errors let a case of seed 3 0.68 point below through, by two
four cases). The margin of a single recording was set on seed 3, where a twentieth let a case 2.4
points below through. On seeds 3 and 4 one case of 72 ended more than 0.1 point below the
generic model (-0.14: a fresh fit that led on the blocks and on the held-out recordings).
With fewer than two held-out chunks (a handful of rows) there is no
standard error, and the model is not adapted.
"""

import numbers

import numpy as np
import pandas as pd

from .._core._compat import Interval, StrOptions, validate_parameter_constraints
from .._core._sequences import Recordings

AUTO = "auto"
#: Relevance factors "auto" tries, from the strongest prior to the weakest (after "do not
#: adapt", ``inf``): a factor 4 apart, from 4096 rows (3.4 minutes at 20 Hz) to 4.
RELEVANCE_CANDIDATES = (4096.0, 1024.0, 256.0, 64.0, 16.0, 4.0)
#: Parameter sets "auto" tries at every relevance: the means and covariances. In
#: ``benchmarks/bench_adapt_defaults.py`` the means alone ("m") were as good only where little
#: moved, at twice the cost of the choice, and the transitions ("t") changed nothing measurable.
PARAMETER_CANDIDATES = ("mv",)
ADAPTED_PARAMETERS = frozenset("mvt")
#: The fresh fit, the weakest candidate: no prior, so every parameter is new.
FRESH_FIT = ("mvt", 0.0)
N_FOLDS = 8
N_CHUNKS = 10
SE_FACTOR = 2.0
#: The fresh fit is considered when it is ahead of the choice among the adapted candidates by
#: this many standard errors of their paired differences on the time folds ...
FRESH_FIT_FACTOR = 0.5
#: ... and chosen unless that choice is ahead of it by this many on held-out recordings ...
RECORDINGS_FACTOR = 1.0
#: ... or, with a single recording, if its score is at least this fraction below the choice's.
SINGLE_RECORDING_MARGIN = 0.1

RELEVANCE_CONSTRAINT = [Interval(numbers.Real, 0, None, closed="both"), StrOptions({AUTO})]


def check_strength(relevance, parameters, caller="adapt"):
    """The validated ``(relevance, parameters)`` of ``adapt``: a float in [0, inf] or "auto",
    and a string of "m", "v" and "t" or "auto" ("mvt" or "auto" with ``relevance=0``, a fresh
    fit); errors name the parameter and the value."""
    validate_parameter_constraints(
        {"relevance": RELEVANCE_CONSTRAINT}, {"relevance": relevance}, caller_name=caller
    )
    relevance = relevance if relevance == AUTO else float(relevance)
    if parameters == AUTO:
        return relevance, AUTO
    if not isinstance(parameters, str) or not set(parameters) <= ADAPTED_PARAMETERS:
        raise ValueError(
            f"The 'parameters' parameter of {caller} must be 'auto' or a string of 'm' "
            f"(means), 'v' (covariances) and 't' (transitions). Got {parameters!r} instead."
        )
    if relevance == 0 and set(parameters) != ADAPTED_PARAMETERS:
        raise ValueError(
            f"relevance=0 fits the model anew, every parameter: the 'parameters' parameter of "
            f"{caller} must then be 'mvt' or 'auto'. Got {parameters!r} instead."
        )
    return relevance, parameters


def candidates(relevance, parameters, fresh_fit=True):
    """The ``(parameters, relevance)`` pairs "auto" compares, in the order of the rule: "do
    not adapt" (``("", inf)``) first, then from the strongest prior to the weakest, the fresh
    fit (:data:`FRESH_FIT`) last when both are "auto" (or ``relevance=0``) and ``fresh_fit``."""
    relevances = RELEVANCE_CANDIDATES if relevance == AUTO else (relevance,)
    sets = PARAMETER_CANDIDATES if parameters == AUTO else (parameters,)
    sets = ["".join(sorted(set(p), key="mvt".index)) for p in sets]
    pairs = [("", np.inf)]
    pairs += [(p, value) for value in relevances for p in sets if p and 0 < value < np.inf]
    if fresh_fit and (relevance == 0 or AUTO == relevance == parameters):
        pairs.append(FRESH_FIT)
    return list(dict.fromkeys(pairs))


def time_folds(recordings, n_folds=N_FOLDS):
    """The folds of ``recordings`` (:class:`~skhmmgmr._core._sequences.Recordings`): a list of
    ``(adapt_rows, adapt_recordings, held_rows, held_recordings)``, the rows as indices into
    the data and the recordings over those rows in that order. Fold ``i`` holds out the
    ``i``-th time block of every recording; a fold without rows on either side is left out."""
    blocks = [
        [np.arange(start, stop)[part] for part in np.array_split(np.arange(stop - start), n_folds)]
        for start, stop in zip(recordings.starts, recordings.stops, strict=True)
    ]
    folds = []
    for i in range(n_folds):
        held = [parts[i] for parts in blocks if parts[i].size]
        adapted = [part for parts in blocks for j, part in enumerate(parts) if j != i and part.size]
        if held and adapted:
            folds.append((*_pieces(adapted), *_pieces(held)))
    return folds


def recording_folds(recordings):
    """The folds of ``recordings`` that hold out one whole recording each, in the form of
    :func:`time_folds`; none with fewer than two recordings."""
    if len(recordings) < 2:
        return []
    parts = [
        np.arange(start, stop)
        for start, stop in zip(recordings.starts, recordings.stops, strict=True)
    ]
    return [
        (*_pieces(parts[:i] + parts[i + 1 :]), *_pieces([held])) for i, held in enumerate(parts)
    ]


def _pieces(parts):
    """The rows of ``parts`` (index arrays) and their recordings, one per part."""
    lengths = np.array([part.size for part in parts])
    stops = np.cumsum(lengths)
    ids = np.arange(len(parts))
    return np.concatenate(parts), Recordings(ids=ids, starts=stops - lengths, stops=stops)


def chunk_ids(recordings, n_chunks=N_CHUNKS):
    """The chunk of every row of ``recordings``: each recording cut into ``n_chunks`` parts of
    (nearly) equal length, numbered in order."""
    ids = np.empty(recordings.stops[-1] if len(recordings) else 0, dtype=np.intp)
    first = 0
    for start, stop in zip(recordings.starts, recordings.stops, strict=True):
        parts = [part for part in np.array_split(np.arange(start, stop), n_chunks) if part.size]
        for j, part in enumerate(parts):
            ids[part] = first + j
        first += len(parts)
    return ids


def chunk_rmse(chunk_errors, counts):
    """The root mean squared error of every candidate (row of ``chunk_errors``, the sums of
    its squared errors per chunk, NaN where it could not adapt) in every chunk with entries
    (``counts``): shape (n_candidates, n_chunks with entries)."""
    kept = np.asarray(counts) > 0
    return np.sqrt(np.asarray(chunk_errors, dtype=float)[:, kept] / np.asarray(counts)[kept])


def ahead(rmse, than, factor):
    """Whether the chunk errors ``rmse`` are ahead of ``than`` (the same chunks) by more than
    ``factor`` standard errors of their difference: the mean of the paired differences below
    ``-factor`` times their spread over the square root of their number. Never with NaN
    (a candidate that could not adapt) or fewer than two chunks."""
    difference = np.asarray(rmse) - np.asarray(than)
    if difference.size < 2 or not np.isfinite(difference).all():
        return False
    se = np.std(difference, ddof=1) / np.sqrt(difference.size)
    return bool(difference.mean() < -factor * se)


def choose(pairs, chunk_errors, counts, se_factor=SE_FACTOR, fresh_factor=FRESH_FIT_FACTOR):
    """The table of the choice on the time folds: one row per candidate of ``pairs`` (in the
    rule's order) with ``parameters``, ``relevance``, ``validation_rmse`` (the mean over the
    held-out chunks of the root mean squared error in the chunk), ``validation_se`` (its
    standard error over the chunks), ``recordings_rmse`` (NaN: filled by
    :func:`confirm_fresh_fit`) and ``chosen``; and whether the fresh fit is to be confirmed
    on held-out recordings.

    ``chunk_errors`` (n_candidates, n_chunks) holds the sums of every candidate's squared
    errors per chunk (NaN where a candidate could not adapt), ``counts`` the entries of every
    chunk (chunks with none are left out). Among the candidates that keep the fitted model as
    a prior ("do not adapt" and the relevance grid) the first within ``se_factor`` standard
    errors of the best one's score is chosen; a fresh fit (:data:`FRESH_FIT`, last in
    ``pairs``) is then to be confirmed when it is :func:`ahead` of that choice by
    ``fresh_factor`` standard errors of their difference."""
    rmse = chunk_rmse(chunk_errors, counts)
    n_chunks = rmse.shape[1]
    score = rmse.mean(axis=1) if n_chunks else np.full(len(pairs), np.nan)
    se = np.full(len(pairs), np.nan)
    fresh = len(pairs) > 1 and pairs[-1] == FRESH_FIT
    chosen, confirm = 0, False  # without two chunks there is no spread to measure: nothing moves
    if n_chunks > 1:
        se = np.std(rmse, axis=1, ddof=1) / np.sqrt(n_chunks)
        prior = slice(0, len(pairs) - 1 if fresh else len(pairs))
        scores = score[prior]
        best = int(np.nanargmin(scores))
        chosen = int(np.argmax(scores <= scores[best] + se_factor * se[best]))  # NaN: never
        confirm = fresh and ahead(rmse[-1], rmse[chosen], fresh_factor)
    table = pd.DataFrame(
        {
            "parameters": [p for p, _ in pairs],
            "relevance": [float(r) for _, r in pairs],
            "validation_rmse": score,
            "validation_se": se,
            "recordings_rmse": np.full(len(pairs), np.nan),
            "chosen": np.arange(len(pairs)) == chosen,
        }
    )
    return table, confirm


def confirm_fresh_fit(table, chunk_errors=None, counts=None):
    """``table`` of :func:`choose` with the fresh fit (its last row) chosen if it holds on
    held-out recordings: unless the choice of the time folds is :func:`ahead` of it there by
    :data:`RECORDINGS_FACTOR` standard errors of their difference (or either has no score
    there). ``chunk_errors`` (2, n_chunks): the sums of squared errors per chunk of the choice
    and of the fresh fit on the :func:`recording_folds`, whose mean root mean squared errors
    go to ``recordings_rmse``. None with a single recording (none to hold out): the fresh fit
    is chosen if its score on the time folds is at least :data:`SINGLE_RECORDING_MARGIN` (a
    fraction) below the choice's."""
    table = table.copy()
    fresh = len(table) - 1
    first = int(np.flatnonzero(table["chosen"])[0])
    if chunk_errors is None:
        scores = table["validation_rmse"].to_numpy()
        if scores[fresh] > (1.0 - SINGLE_RECORDING_MARGIN) * scores[first]:
            return table
    else:
        rmse = chunk_rmse(chunk_errors, counts)
        table.loc[[first, fresh], "recordings_rmse"] = rmse.mean(axis=1)
        if rmse.shape[1] < 2 or not np.isfinite(rmse).all():
            return table
        if ahead(rmse[0], rmse[1], RECORDINGS_FACTOR):
            return table
    table["chosen"] = np.arange(len(table)) == fresh
    return table
