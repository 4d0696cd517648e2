"""State selection of the thesis (Section IV-D, Appendix D.4): the number of states K.

Public through :mod:`skhmmgmr.state_selection`.

With the feature subset fixed, models with K = 1..K_max are fitted on the training recordings
and judged on every validation recording with the performance score. K grows while the score
improves by more than 1%:

- ``average`` method: on the score averaged over the validation recordings;
- ``per_recording`` method: on each recording separately, then the selected K are averaged over
  the recordings and rounded half up (2.5 -> 3);

and the final K is the smaller of the two. The BIC of every K on the training recordings is
kept for comparison (the usual, likelihood-only alternative).

The plain scikit-learn route works too: ``GridSearchCV`` over ``n_states`` with
``GroupKFold`` and several :class:`~skhmmgmr.PerformanceScore` trade-offs as multi-metric
scoring (see :func:`skhmmgmr.metrics.make_performance_scorers`) gives the mean score of every K
per trade-off; it picks the best K, not the first K after which the gain falls below 1%.
"""

from numbers import Integral, Real

import numpy as np
import pandas as pd
from sklearn.base import BaseEstimator, RegressorMixin, clone
from sklearn.exceptions import NotFittedError
from sklearn.utils.validation import check_is_fitted

from ..._core._compat import Interval, _fit_context, validate_params
from ..._core._docstrings import fill_shared_parameters
from ..._core._pickled import PickleVersionMixin
from ...metrics._scores import trade_offs as all_trade_offs
from .._search._score_tables import labels_of, relative_gain, rescore_table
from .._search.base import RecordingSearchMixin, search_constraints

# The 1% rule: K grows while one more state improves the score by more than ``tol``.
TOL = [Interval(Real, 0, None, closed="left")]
K_RANGE = {
    "k_min": [Interval(Integral, 1, None, closed="left")],
    "k_max": [Interval(Integral, 1, None, closed="left")],
}


def _stop(scores, tol):
    """Position of the smallest K from which one more state improves ``scores`` (in order of
    K) by no more than ``tol``: the rule reads the scores up to the next position."""
    i = 0
    while i + 1 < len(scores) and relative_gain(scores[i], scores[i + 1]) > tol:
        i += 1
    return i


def _grow_while_gain(n_states, scores, tol):
    """Smallest K from which one more state improves the score by no more than ``tol``."""
    return int(n_states[_stop(scores, tol)])


def read_by_the_rule(scores, tol, score="performance_score"):
    """The K whose scores decide :func:`state_choices`'s ``n_states`` for a table of one
    trade-off: a prefix of the K (in order).

    The average method reads every K up to one past its choice. The per-recording method
    reads each recording's scores up to one past its own choice, but the decision, the
    smaller of the two methods' K, needs them only as far as the rounded mean of the
    recordings' choices is known to reach the average method's K: a recording that improves
    by more than ``tol`` at every K read chooses at least the last of them. The prefix read
    is the shortest that settles the decision, or the one that knows every recording's
    choice.
    """
    wide = scores.pivot_table(index="n_states", columns="recording", values=score, sort=True)
    ks = wide.index.to_numpy()
    average = _stop(wide.mean(axis=1).to_numpy(), tol)
    stops = np.array([_stop(wide[recording].to_numpy(), tol) for recording in wide])
    for length in range(min(average + 2, len(ks)), len(ks) + 1):
        # with the first ``length`` K read, a recording chooses at least the last of them
        lowest = ks[np.minimum(stops, length - 1)]
        if np.floor(lowest.mean() + 0.5) >= ks[average] or np.all(stops + 2 <= length):
            break
    return [int(k) for k in ks[:length]]


@validate_params(
    {"scores": [pd.DataFrame], "tol": TOL, "score": [str]},
    prefer_skip_nested_validation=True,
)
def state_choices(scores, *, tol=0.01, score="performance_score"):
    """Apply the thesis' 1% rule to a table of scores of K = 1..K_max.

    Parameters
    ----------
    scores : pandas.DataFrame
        One row per (K, recording) and optionally per trade-off, with columns ``n_states``,
        ``recording``, ``score`` (lower is better) and, optionally, ``trade_off``.
    tol : float, default=0.01
        K grows while one more state improves the score by more than this fraction.
    score : str, default="performance_score"
        Column holding the score.

    Returns
    -------
    choices : pandas.DataFrame
        One row per trade-off: ``n_states_average`` (rule on the mean over recordings),
        ``n_states_per_recording_mean`` (mean of the per-recording choices),
        ``n_states_per_recording`` (that mean rounded half up) and ``n_states`` (the minimum
        of the two methods).

    Examples
    --------
    >>> import pandas as pd
    >>> from skhmmgmr.state_selection import state_choices
    >>> scores = pd.DataFrame({
    ...     "n_states": [1, 2, 3, 1, 2, 3],
    ...     "recording": ["a", "a", "a", "b", "b", "b"],
    ...     "performance_score": [1.0, 0.5, 0.499, 1.0, 0.9, 0.5],
    ... })
    >>> state_choices(scores)[["n_states_average", "n_states_per_recording", "n_states"]]
       n_states_average  n_states_per_recording  n_states
    0                 3                       3         3
    """
    table = scores if "trade_off" in scores.columns else scores.assign(trade_off="")
    rows = []
    for label, block in table.groupby("trade_off", sort=False):
        wide = block.pivot_table(index="n_states", columns="recording", values=score, sort=True)
        ks = wide.index.to_numpy()
        average = _grow_while_gain(ks, wide.mean(axis=1).to_numpy(), tol)
        per_recording = [_grow_while_gain(ks, wide[rec].to_numpy(), tol) for rec in wide]
        mean = float(np.mean(per_recording))
        rounded = int(np.floor(mean + 0.5))
        rows.append(
            {
                "trade_off": label,
                "n_states_average": average,
                "n_states_per_recording_mean": mean,
                "n_states_per_recording": rounded,
                "n_states": min(average, rounded),
            }
        )
    choices = pd.DataFrame(rows)
    return choices if "trade_off" in scores.columns else choices.drop(columns="trade_off")


@fill_shared_parameters
class StateSelector(PickleVersionMixin, RecordingSearchMixin, RegressorMixin, BaseEstimator):
    """Choose the number of states K by the thesis' 1% rule on validation recordings.

    Fits a clone of ``estimator`` for every K in ``k_min..k_max`` on the training recordings of
    each ``cv`` split, evaluates it on every validation recording, normalises the metrics over
    the compared K (D.5) and applies :func:`state_choices`. With ``refit=True`` the estimator
    is then fitted with the chosen K on all rows given to ``fit``, and ``predict`` uses it.

    Parameters
    ----------
    {estimator}
    {k_min, k_max}
    tol : float, default=0.01
        Relative gain below which K stops growing.
    param_name : str, default="n_states"
        Parameter set to K (e.g. ``"hmmgmrregressor__n_states"`` in a pipeline).
    refit : bool, default=True
        Fit ``best_estimator_`` with the chosen K on all the data.
    {search parameters}

    Attributes
    ----------
    results_ : pandas.DataFrame
        One row per (K, validation recording): ``n_states``, ``fold``, ``recording``,
        ``n_samples``, ``rmse``, ``accuracy``, ``smoothness``, ``converged``, ``bic``.
    bic_ : pandas.DataFrame
        BIC of every K on the training recordings (summed over splits).
    choices_ : pandas.DataFrame
        :func:`state_choices` at ``accuracy_weight``/``smoothness_weight``.
    n_states_ : int
        Chosen K (minimum of the two methods).
    n_states_bic_ : int
        K of the lowest BIC, for comparison.
    best_estimator_ : estimator
        Refitted estimator (``refit=True``).

    Examples
    --------
    >>> import numpy as np
    >>> from sklearn.model_selection import PredefinedSplit
    >>> from skhmmgmr.state_selection import StateSelector
    >>> rng = np.random.default_rng(0)
    >>> X = np.cumsum(rng.normal(scale=0.1, size=(400, 1)), axis=0)
    >>> y = np.abs(X[:, 0]) + 0.01 * rng.normal(size=400)
    >>> groups = np.repeat([0, 1, 2, 3], 100)
    >>> cv = PredefinedSplit(np.where(groups >= 2, 0, -1))
    >>> selector = StateSelector(k_max=3, cv=cv, sampling_period=0.1).fit(X, y, groups=groups)
    >>> selector.results_["n_states"].unique().tolist()
    [1, 2, 3]
    """

    _parameter_constraints = {
        **RecordingSearchMixin._parameter_constraints,
        **K_RANGE,
        "tol": TOL,
        "param_name": [str],
        "refit": ["boolean"],
    }
    __metadata_request__predict = {"groups": True}

    def __init__(
        self,
        estimator=None,
        *,
        k_min=1,
        k_max=20,
        tol=0.01,
        param_name="n_states",
        refit=True,
        cv=5,
        accuracy_weight=0.5,
        smoothness_weight=0.5,
        sampling_period=None,
        n_jobs=None,
        memory=None,
        verbose=0,
        search="full",
    ):
        super().__init__(
            estimator,
            cv=cv,
            accuracy_weight=accuracy_weight,
            smoothness_weight=smoothness_weight,
            sampling_period=sampling_period,
            n_jobs=n_jobs,
            memory=memory,
            verbose=verbose,
            search=search,
        )
        self.k_min = k_min
        self.k_max = k_max
        self.tol = tol
        self.param_name = param_name
        self.refit = refit

    @_fit_context(prefer_skip_nested_validation=False)
    def fit(self, X, y, groups=None):
        """Evaluate K = k_min..k_max and choose K.

        Parameters
        ----------
        X : array-like of shape (n_samples, n_features)
            The fixed feature subset of the training and validation recordings.
        y : array-like of shape (n_samples,)
        groups : array-like of shape (n_samples,), default=None
            Recording id of every row.

        Returns
        -------
        self : StateSelector
        """
        if self.k_min > self.k_max:
            raise ValueError(f"k_min={self.k_min} > k_max={self.k_max}")
        given = X  # refit on it: best_estimator_ then knows the feature names
        X, y, groups, splits = self._validate_search(X, y, groups)
        ks = list(range(self.k_min, self.k_max + 1))  # fitted largest first (evaluate_models)
        columns = tuple(range(X.shape[1]))
        models = [(columns, {self.param_name: k}) for k in ks]

        def settle(table):
            # the K the rule reads at this trade-off are fitted as the full search does
            results = table.assign(n_states=[ks[i] for i in table["model"]])
            scores = rescore_table(results, "n_states", self._trade_off)
            return [ks.index(k) for k in read_by_the_rule(scores, self.tol)]

        with self._searching(X, y, groups, splits):
            table = self._evaluate_models(
                X, y, groups, splits, models, "number of states", with_bic=True, settle=settle
            )
        table.insert(0, "n_states", [ks[i] for i in table["model"]])
        self.results_ = (
            table.drop(columns="model")
            .sort_values(["n_states", "fold"], kind="stable")
            .reset_index(drop=True)
        )
        per_fold = self.results_.drop_duplicates(["n_states", "fold"])
        self.bic_ = per_fold.groupby("n_states", as_index=False)["bic"].sum()
        self.n_states_bic_ = int(self.bic_.loc[self.bic_["bic"].idxmin(), "n_states"])
        self.choices_ = self.choices(self._trade_off)
        self.n_states_ = int(self.choices_["n_states"].iloc[0])
        if self.refit:
            chosen = {self.param_name: self.n_states_}
            self.best_estimator_ = clone(self._search_estimator()).set_params(**chosen)
            self.best_estimator_.fit(given, y, groups=groups)
        elif hasattr(self, "best_estimator_"):
            del self.best_estimator_  # that of an earlier fit: it would predict with a stale K
        return self

    def rescore(self, trade_off="50/50"):
        """D.5-normalised performance score of every (K, recording), without refitting."""
        check_is_fitted(self, "results_")
        return rescore_table(self.results_, "n_states", trade_off)

    def choices(self, trade_off="50/50"):
        """:func:`state_choices` for the given trade-off(s)."""
        return state_choices(self.rescore(labels_of(trade_off)), tol=self.tol)

    def predict(self, X, groups=None):
        """Predict with ``best_estimator_`` (the chosen K)."""
        check_is_fitted(self, "results_")
        if not hasattr(self, "best_estimator_"):
            raise NotFittedError(
                f"this StateSelector was fitted with refit=False, so no estimator was refitted "
                f"with the chosen n_states_={self.n_states_} and it cannot predict: set "
                "refit=True, or fit the estimator with that number of states yourself"
            )
        # fitted on X as given to fit: it checks the number of features and their names
        return self.best_estimator_.predict(X, groups=groups)


@validate_params(
    {
        "X": ["array-like", "sparse matrix"],  # sparse: refused by fit, saying what to do
        "y": ["array-like"],
        "groups": ["array-like", None],
        "tol": TOL,
        "trade_offs": [str, list, tuple, None],
    }
    | K_RANGE
    | search_constraints(
        "estimator", "cv", "sampling_period", "n_jobs", "memory", "verbose", "search"
    ),
    prefer_skip_nested_validation=False,  # the estimator's own parameters are checked in fit
)
@fill_shared_parameters
def select_n_states(
    X,
    y,
    groups=None,
    *,
    estimator=None,
    k_min=1,
    k_max=20,
    tol=0.01,
    cv=5,
    trade_offs=None,
    sampling_period=None,
    n_jobs=None,
    memory=None,
    verbose=0,
    search="full",
):
    """Scores of K = k_min..k_max on validation recordings and the K chosen per trade-off.

    A function front end of :class:`StateSelector` (without refit).

    Parameters
    ----------
    X : array-like of shape (n_samples, n_features)
        The fixed feature subset of the training and validation recordings.
    y : array-like of shape (n_samples,)
        Target (driver torque).
    {groups}
    trade_offs : list of str, default=None
        Trade-offs to choose K for; ``None`` means "100/0" to "0/100" in steps of 10%.
    {estimator}
    {k_min, k_max}
    tol : float, default=0.01
        Relative gain below which K stops growing.
    {cv}
    {sampling_period}
        Required: every search scores the smoothness.
    {n_jobs}
    {memory}
    {verbose}
    {search}

    Returns
    -------
    scores : pandas.DataFrame
        One row per (trade-off, K, recording) with the metrics, the BIC of the training
        recordings and the normalised ``performance_score``.
    choices : pandas.DataFrame
        One row per trade-off; see :func:`state_choices`.
    """
    selector = StateSelector(
        estimator,
        k_min=k_min,
        k_max=k_max,
        tol=tol,
        refit=False,
        cv=cv,
        sampling_period=sampling_period,
        n_jobs=n_jobs,
        memory=memory,
        verbose=verbose,
        search=search,
    ).fit(X, y, groups=groups)
    labels = all_trade_offs(10) if trade_offs is None else labels_of(trade_offs)
    scores = selector.rescore(labels)
    return scores, state_choices(scores, tol=tol)
