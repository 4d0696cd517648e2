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
    Parallel fits through joblib (any backend, e.g. ``joblib.parallel_backend("dask")``).
    joblib's default process backend (loky) keeps its workers for the next search until they
    have idled ``idle_worker_timeout`` seconds (300; set it with
    ``joblib.parallel_config(backend="loky", idle_worker_timeout=...)``). Ctrl-C ends them at
    once; after a run killed outright (SIGTERM, SIGKILL) they exit after that timeout (and
    up to 30 s more), and the temporary copy of the data they read is deleted then.""",
    "memory": """\
memory : str or joblib.Memory, default=None
    Cache of every (model, split) evaluation: a repeated or interrupted search resumes from it
    without refitting. Results are keyed by the versions of skhmmgmr (and its source) and of
    NumPy, SciPy, scikit-learn and numba too: another version recomputes them.""",
    "verbose": """\
verbose : int, default=0
    Show a progress bar when positive.""",
    "search": """\
search : {"full", "fast"}, default="full"
    How the compared models are fitted. ``"full"``: each from its own start (the estimator's
    k-means) until EM converges. ``"fast"``: every feature subset (but the forward wrapper's
    single features) is scored as the marginal of one model fitted on all the searched
    features (no EM iteration of its own), the numbers of states grow one split of a state
    at a time, each with a few EM iterations, and the models a decision reads (the K of the
    1% rule) are fitted as ``"full"`` fits them. The fast
    search serves a plain :class:`~skhmmgmr.HMMGMRRegressor` with complete data, no read-out
    and one output; any other estimator is searched in full. It is opt-in: its screened
    models sit in other EM optima than the full search's, and some selections differ as they
    do between two k-means starts of the full search. See the user guide, "The
    parameter-selection framework".""",
    "k_min, k_max": """\
k_min, k_max : int, default=1, 20
    Range of K, the number of hidden states.""",
    # selectors and scorers
    "sampling_period": """\
sampling_period : float, default=None
    Seconds between two rows, for time derivatives (the smoothness of the estimate) and time
    constants.""",
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
    # metric functions
    "y_true": """\
y_true : array-like of shape (n_samples,) or (n_samples, n_outputs)
    Observed target (driver torque).""",
    "y_pred": """\
y_pred : array-like of shape (n_samples,) or (n_samples, n_outputs)
    Estimated target.""",
    "groups": """\
groups : array-like of shape (n_samples,), default=None
    Recording id of every row; the rows of a recording must be contiguous. ``None`` means
    all rows form one recording.""",
    "time": """\
time : array-like of shape (n_samples,), default=None
    Time stamp of every row in seconds, strictly increasing within each recording.""",
    "multioutput": """\
multioutput : {"uniform_average", "raw_values"} or array-like of shape (n_outputs,), \
        default="uniform_average"
    How to combine several outputs: their plain mean, one value per output, or a weighted
    mean.""",
}

# Names for runs of shared entries that always come together, in this order; an item is a key
# of SHARED_PARAMETERS or a (key, sentence added to its description) pair.
SHARED_GROUPS = {
    "search parameters": (
        "cv",
        "accuracy_weight, smoothness_weight",
        ("sampling_period", "Required: every search scores the smoothness."),
        "n_jobs",
        "memory",
        "verbose",
        "search",
    ),
    "y_true, y_pred": ("y_true", "y_pred"),
}

_PLACEHOLDER = re.compile(r"^( *)\{([a-z_, ]+)\}$", re.MULTILINE)


def fill_shared_parameters(obj):
    """Decorator of a class or function: replace the ``{name}`` lines of its docstring by the
    shared entries."""

    def entry(match):
        indent, name = match.groups()
        items = [(i, "") if isinstance(i, str) else i for i in SHARED_GROUPS.get(name, (name,))]
        if not all(key in SHARED_PARAMETERS for key, _ in items):
            return match.group(0)
        entries = [
            SHARED_PARAMETERS[key] + (f"\n    {note}" if note else "") for key, note in items
        ]
        return "\n".join(textwrap.indent(entry, indent) for entry in entries)

    if obj.__doc__:
        obj.__doc__ = _PLACEHOLDER.sub(entry, obj.__doc__)
    return obj
