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

The choice is the one-standard-error rule of cross-validation (Hastie, Tibshirani and
Friedman, *The Elements of Statistical Learning*, 7.10), towards the fitted model: the chosen
candidate is the first, in the order "do not adapt", then relevance from the largest to the
smallest, then the fresh fit, whose score is at most the best score plus :data:`SE_FACTOR`
standard errors of it (the spread of the best candidate's chunk errors over the square root
of their number). A gain that the held-out chunks cannot tell from chance does not move the
model: the data of the fitted model's own drivers keep it as it is, while a driver far from
it moves it as far as the held-out rows support. Then the chosen candidate adapts to (or is
fitted on) all the rows.

The constants were chosen on ``benchmarks/bench_adapt_defaults.py`` (simulated drivers held
out of a generic model in four cars, 1 to 5 minutes of adaptation data, data seeds 0-2) and
checked on seeds 3 and 4: eight folds rather than two to five, whose adaptations see too few
rows to judge the weak priors and the fresh fit; the chunks' root mean squared errors rather
than their squared errors, whose few large values make the standard error wide; the standard
error of the best candidate's score rather than of each candidate's difference to it, which
let a noisy candidate through; two standard errors (one and a half left three cases of 108
more than 0.1 point below the generic model, two one case, and none of the 72 of seeds 3 and
4). With fewer than two held-out chunks (a handful of rows) there is no standard error, and
the model is not adapted.
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


def choose(pairs, chunk_errors, counts, se_factor=SE_FACTOR):
    """The table of the choice: one row per candidate of ``pairs`` (in the rule's order) with
    ``parameters``, ``relevance``, ``validation_rmse`` (the mean over the held-out chunks of
    the root mean squared error in the chunk), ``validation_se`` (its standard error over the
    chunks) and ``chosen``: the first candidate within ``se_factor`` standard errors of the
    best one's score. ``chunk_errors`` (n_candidates, n_chunks) holds the sums of every
    candidate's squared errors per chunk (NaN where a candidate could not adapt), ``counts``
    the entries of every chunk (chunks with none are left out)."""
    kept = np.asarray(counts) > 0
    errors, counts = np.asarray(chunk_errors, dtype=float)[:, kept], np.asarray(counts)[kept]
    n_chunks = counts.size
    rmse = np.sqrt(errors / counts)
    score = rmse.mean(axis=1) if n_chunks else np.full(len(pairs), np.nan)
    se = np.full(len(pairs), np.nan)
    chosen = 0  # without two chunks there is no spread to measure: nothing moves
    if n_chunks > 1:
        se = np.std(rmse, axis=1, ddof=1) / np.sqrt(n_chunks)
        best = int(np.nanargmin(score))
        chosen = int(np.argmax(score <= score[best] + se_factor * se[best]))  # NaN: never
    return pd.DataFrame(
        {
            "parameters": [p for p, _ in pairs],
            "relevance": [float(r) for _, r in pairs],
            "validation_rmse": score,
            "validation_se": se,
            "chosen": np.arange(len(pairs)) == chosen,
        }
    )
