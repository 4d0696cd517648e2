"""Parameter descriptions shared by several public classes, written once.

A docstring names a shared parameter by a line holding only ``{name}`` at the indentation of
its ``Parameters`` entries; :func:`fill_shared_parameters` replaces the line with the entry of
:data:`SHARED_PARAMETERS` (continuation lines indented to match), or with the entries of a
group of :data:`SHARED_GROUPS`. Only the registered names are
replaced, so other braces in a docstring (sets of options, formulas) are left alone.
``tests/test_docstrings.py`` checks that every public class taking a shared parameter
describes it with the shared entry.
"""

import re
import textwrap

SHARED_PARAMETERS = {
    # selectors that search over recordings (and, for the trade-off, the scorers)
    "estimator": """\
estimator : estimator, default=None
    Regressor with ``fit(X, y, groups=...)`` and ``predict(X, groups=...)`` that the search
    fits; ``None`` means a seeded :class:`~skhmmgmr.HMMGMRRegressor` (K=2 for the feature
    searches, the thesis' choice), so that the compared models differ by what is searched
    only.""",
    "cv": """\
cv : int, splitter or iterable, default=5
    Training/validation split(s) of the recordings. An int means ``GroupKFold(cv)``; the
    thesis' fixed validation set is a ``PredefinedSplit`` (0 on validation rows, -1 on
    training rows). Every recording may be validated in one split only.""",
    "accuracy_weight, smoothness_weight": """\
accuracy_weight, smoothness_weight : float, default=0.5
    Trade-off weights ``w1`` (accuracy) and ``w2`` (smoothness) of the performance score.""",
    "n_jobs": """\
n_jobs : int, default=None
    Parallel fits through joblib (any backend, e.g. ``joblib.parallel_backend("dask")``).""",
    "memory": """\
memory : str or joblib.Memory, default=None
    Cache of every (model, split) evaluation: a repeated or interrupted search resumes from it
    without refitting.""",
    "verbose": """\
verbose : int, default=0
    Show a progress bar when positive.""",
    # selectors and scorers
    "sampling_period": """\
sampling_period : float, default=None
    Seconds between two rows, for the smoothness. The selectors require it; a scorer may
    read the time from ``time_column`` instead.""",
    # scorers
    "time_column": """\
time_column : str, default=None
    Alternatively, the name of a column of ``X`` (a pandas DataFrame) holding the time in
    seconds. The column stays in ``X`` for the estimator, which must ignore or use it.""",
    "predict_mode": """\
predict_mode : {"auto", "groups", "per_recording"}, default="auto"
    How the fold is predicted when ``groups`` is known. ``"groups"``: one call
    ``estimator.predict(X, groups=groups)`` (the estimator restarts its filter at every
    recording). ``"per_recording"``: one ``estimator.predict`` call per recording, which
    works for any estimator or pipeline. ``"auto"``: ``"groups"`` if ``predict`` has a
    ``groups`` parameter, else ``"per_recording"``.""",
}

# Names for runs of shared entries that always come together, in this order.
SHARED_GROUPS = {
    "search parameters": (
        "cv",
        "accuracy_weight, smoothness_weight",
        "sampling_period",
        "n_jobs",
        "memory",
        "verbose",
    ),
}

_PLACEHOLDER = re.compile(r"^( *)\{([a-z_, ]+)\}$", re.MULTILINE)


def fill_shared_parameters(obj):
    """Class decorator: replace the ``{name}`` lines of ``obj.__doc__`` by the shared entries."""

    def entry(match):
        indent, name = match.groups()
        names = SHARED_GROUPS.get(name, (name,))
        if not all(key in SHARED_PARAMETERS for key in names):
            return match.group(0)
        return "\n".join(textwrap.indent(SHARED_PARAMETERS[key], indent) for key in names)

    if obj.__doc__:
        obj.__doc__ = _PLACEHOLDER.sub(entry, obj.__doc__)
    return obj
