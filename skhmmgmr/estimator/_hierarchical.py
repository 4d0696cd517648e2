"""Manoeuvres as a hierarchy: one HMM-GMR per manoeuvre, sequenced by a Markov chain.

The two levels are fitted and kept as one flat HMM-GMR whose transition matrix has the block
structure of :mod:`skhmmgmr._hmm._hierarchy`; the regressor's causal filter, ``predict``
with ``return_std``, the streaming filter, the model file and the C export read that flat
model as they read any other.
"""

import warnings
from collections.abc import Mapping, Set
from numbers import Integral, Number

import numpy as np
from sklearn.exceptions import ConvergenceWarning
from sklearn.utils.validation import check_is_fitted

from .._core._compat import Interval, InvalidParameterError, StrOptions, _fit_context
from .._core._panel import read_layout
from .._hmm._emissions import emission_family
from .._hmm._hierarchy import Hierarchy
from .._hmm._hierarchy_em import HierarchyEM
from .._hmm._portable import HIERARCHICAL_TYPE
from ._prediction_inputs import read_joint_inputs
from ._regressor import HMMGMRRegressor


class HierarchicalHMMGMRRegressor(HMMGMRRegressor):
    """HMM-GMR whose hidden states are organised by manoeuvre, the manoeuvres by a Markov chain.

    Every manoeuvre (lane keeping, lane change, overtaking, evasive action...) has its own
    HMM over the joint vector ``[X, y]``, whose states model the lower-level behaviour; a
    Markov chain sequences the manoeuvres (thesis Appendix E.3, after Pentland and Liu). The
    two levels form one flat HMM over all states, whose transition matrix has one block per
    manoeuvre: within manoeuvre ``m``, ``(1 - x_mi) B_m[i, j]``; from state ``i`` of ``m`` to
    state ``j`` of another manoeuvre ``n``, ``x_mi C[m, n] e_n[j]`` (``B_m`` the manoeuvre's
    own transitions, ``x_mi`` the probability of leaving it from state ``i``, ``C`` the chain,
    ``e_n`` the entry distribution of ``n``). Prediction is the causal GMR filter of
    :class:`HMMGMRRegressor` on that flat HMM, which is exactly the two-level filter; the
    filtered probability of a manoeuvre is the sum of its states'
    (:meth:`predict_manoeuvre_proba`).

    With manoeuvre labels per row, ``fit`` fits every manoeuvre's HMM on its segments (runs
    of rows of one label within a recording), the chain, the exit probabilities and the start
    probabilities from the label sequence, then refines all of them jointly by EM on the
    unlabelled rows, keeping the block structure. Without labels, the rows are first
    labelled by k-means on ``[X, y]`` (one cluster per manoeuvre) and EM runs from there.

    :meth:`~HMMGMRRegressor.adapt` works as the flat model's, except that its "auto" choice is
    among "do not adapt" and MAP adaptations of the means and covariances (the transitions, and
    so the manoeuvres' structure, stay): a fresh fit (``relevance=0``) needs the manoeuvre
    labels, which ``adapt`` does not take; call ``fit`` for one.

    Read more in the user guide, "Manoeuvres as a hierarchy".

    Parameters
    ----------
    manoeuvres : int, list of str or None, default=2
        The manoeuvres, in the order of their blocks of states. An int: that many manoeuvres,
        named ``0, 1, ...`` (the labels, when given, are those integers). A list: their names
        (the labels must be among them). None: the distinct labels given to ``fit``, sorted
        (then ``fit`` needs the labels).
    n_states : int, list of int or dict, default=2
        States per manoeuvre: the same for all, one per manoeuvre in order, or a mapping
        manoeuvre name -> states naming every manoeuvre.
    covariance_type : {"full", "tied"}, default="full"
        As :class:`HMMGMRRegressor` ("tied": one covariance for the states of all manoeuvres).
    n_iter : int, default=100
        Maximum EM iterations of every manoeuvre's fit, and of the joint EM without labels.
    refine_iter : int, default=10
        EM iterations of the joint refinement after a fit with labels, at most (0: keep the
        parameters read from the labels). A budget: stopping before convergence is not
        warned about.
    start : {"labels", "flat"}, default="labels"
        Where the joint EM starts. "labels": every manoeuvre's HMM fitted on its rows, with
        ``n_states`` states. "flat": the flat HMM-GMR with as many states in total
        (``sum(n_states)``, fitted as :class:`HMMGMRRegressor` with the same ``random_state``
        would be), every state given to the manoeuvre whose rows hold most of its posterior
        probability (a manoeuvre left without one takes the state where its share is
        largest, from a manoeuvre with several), so that ``states_per_manoeuvre_`` may differ
        from ``n_states``; the flat model's densities are kept and the hierarchy's
        transitions estimated from its expected transitions. On the simulator's manoeuvres
        "flat" predicts the torque as the flat model does, "labels" recognises the
        manoeuvres earlier (user guide, "Manoeuvres as a hierarchy"). Without labels, the
        k-means manoeuvres name the states.
    tol : float, default=1e-4
        Convergence threshold on the gain in log-likelihood per row.
    n_init : int, default=1
        Initialisations of every manoeuvre's fit (with labels) or of the k-means start
        (without); the best log-likelihood is kept.
    init_params : {"kmeans", "k-means++", "random", "random_from_data"}, default="kmeans"
        Initialisation of every manoeuvre's states (see :class:`HMMGMRRegressor`).
    reg_covar : float, default=1e-6
        Regularisation of the state covariances (see :class:`HMMGMRRegressor`).
    missing_values : {"error", "marginalize", "carry_forward"}, default="error"
        What a NaN means (see :class:`HMMGMRRegressor`).
    output_smoothing : None, float in [0, 1e6] or "auto", default=None
        Causal first-order read-out of the estimate (see :class:`HMMGMRRegressor`).
    min_log_density : float or None, default=None
        The outlier policy: which samples the filter holds (see :class:`HMMGMRRegressor`).
    random_state : int, RandomState instance or None, default=None
        Seed of the initialisations.
    verbose : int, default=0
        Print the log-likelihood of every joint EM iteration when positive.

    Attributes
    ----------
    manoeuvres_ : ndarray of shape (n_manoeuvres,)
        Names of the manoeuvres, in the order of their blocks.
    states_per_manoeuvre_ : ndarray of shape (n_manoeuvres,)
        States of every manoeuvre.
    state_manoeuvre_ : ndarray of shape (n_states_total,)
        Index (into ``manoeuvres_``) of the manoeuvre of every state.
    manoeuvre_transmat_ : ndarray of shape (n_manoeuvres, n_manoeuvres)
        The chain ``C`` over manoeuvres: zero diagonal, rows summing to one (with one
        manoeuvre, a zero).
    exit_proba_ : ndarray of shape (n_states_total,)
        Probability ``x_mi`` of leaving the state's manoeuvre at the next row.
    entry_proba_ : ndarray of shape (n_states_total,)
        Entry distribution ``e_m`` of every manoeuvre over its states (sums to one per
        manoeuvre).
    manoeuvre_startprob_ : ndarray of shape (n_manoeuvres,)
        Probability of every manoeuvre at the start of a recording.
    startprob_, transmat_, means_, covars_, model_, n_features_in_, feature_names_in_, \
n_outputs_, n_iter_, converged_, log_likelihood_, log_likelihood_history_, \
penalized_log_likelihood_, penalized_log_likelihood_history_, longest_recording_, \
output_smoothing_
        Those of the flat HMM, as in :class:`HMMGMRRegressor` (``n_iter_`` and the histories
        are those of the joint EM).

    See Also
    --------
    HMMGMRRegressor : the flat model.

    Examples
    --------
    >>> import numpy as np
    >>> from skhmmgmr import HierarchicalHMMGMRRegressor
    >>> rng = np.random.default_rng(0)
    >>> X = np.concatenate([rng.normal(-2, 0.5, (300, 1)), rng.normal(2, 0.5, (300, 1))])
    >>> y = np.where(X[:, 0] < 0, 3.0 * X[:, 0], -X[:, 0]) + rng.normal(0, 0.05, 600)
    >>> labels = np.repeat(["keep", "change"], 300)
    >>> model = HierarchicalHMMGMRRegressor(
    ...     manoeuvres=["keep", "change"], n_states=1, random_state=0
    ... ).fit(X, y, manoeuvre=labels)
    >>> model.predict_manoeuvre_proba(X[[0, -1]]).round(2)
    array([[1., 0.],
           [0., 1.]])
    """

    _parameter_constraints = {
        **HMMGMRRegressor._parameter_constraints,
        "manoeuvres": [Interval(Integral, 1, None, closed="left"), "array-like", None],
        "n_states": [Interval(Integral, 1, None, closed="left"), "array-like", Mapping],
        "refine_iter": [Interval(Integral, 0, None, closed="left")],
        "start": [StrOptions({"labels", "flat"})],
    }

    __metadata_request__fit = {"groups": True, "manoeuvre": True}
    __skhmmgmr_model_type__ = HIERARCHICAL_TYPE

    def __init__(
        self,
        manoeuvres=2,
        n_states=2,
        *,
        covariance_type="full",
        n_iter=100,
        refine_iter=10,
        start="labels",
        tol=1e-4,
        n_init=1,
        init_params="kmeans",
        reg_covar=1e-6,
        missing_values="error",
        output_smoothing=None,
        min_log_density=None,
        random_state=None,
        verbose=0,
    ):
        self.manoeuvres = manoeuvres
        self.n_states = n_states
        self.covariance_type = covariance_type
        self.n_iter = n_iter
        self.refine_iter = refine_iter
        self.start = start
        self.tol = tol
        self.n_init = n_init
        self.init_params = init_params
        self.reg_covar = reg_covar
        self.missing_values = missing_values
        self.output_smoothing = output_smoothing
        self.min_log_density = min_log_density
        self.random_state = random_state
        self.verbose = verbose

    # A fresh fit needs the manoeuvres' labels: adapt's "auto" chooses among MAP adaptations.
    _fits_anew = False

    # -- the structure: manoeuvre names and their states ----------------------------------------
    def _set_structure(self, names, sizes):
        for attribute, value in _structure_attributes(names, sizes).items():
            setattr(self, attribute, value)

    def _hierarchy(self):
        return Hierarchy(self.states_per_manoeuvre_)

    def total_states(self):
        """The number of states of the flat model the parameters give (the sum over the
        manoeuvres), or None when it depends on the labels of ``fit`` (``manoeuvres=None``).

        Examples
        --------
        >>> from skhmmgmr import HierarchicalHMMGMRRegressor
        >>> model = HierarchicalHMMGMRRegressor(manoeuvres=["keep", "change"], n_states=[3, 2])
        >>> model.total_states()
        5
        """
        if self.manoeuvres is None:
            return None
        return sum(_states_per_manoeuvre(self.n_states, _manoeuvre_names(self.manoeuvres)))

    # -- fit ------------------------------------------------------------------------------------
    @_fit_context(prefer_skip_nested_validation=True)
    def fit(self, X, y, groups=None, time=None, manoeuvre=None):
        """Fit every manoeuvre's HMM and the chain over manoeuvres, then refine them jointly.

        Parameters
        ----------
        X : array-like of shape (n_samples, n_features)
            Input features, rows of a recording contiguous and in time order, or a DataFrame
            with the recordings (and the time) in its index.
        y : array-like of shape (n_samples,) or (n_samples, n_outputs)
            Outputs (the driver torque).
        groups : array-like of shape (n_samples,), default=None
            Recording id of every row.
        time : array-like of shape (n_samples,), default=None
            Optional time stamps, checked to increase within every recording.
        manoeuvre : array-like of shape (n_samples,), default=None
            The manoeuvre of every row (in the row order of ``X``), one of ``manoeuvres``.
            Routed as metadata (requested by default when metadata routing is enabled).
            Without it the manoeuvres are found by k-means and EM.

        Returns
        -------
        self : HierarchicalHMMGMRRegressor
        """
        emission_family(self.covariance_type)
        labels = None if manoeuvre is None else _Labels.read(manoeuvre, X, groups, time)
        names = _manoeuvre_names(self.manoeuvres, labels)
        sizes = _states_per_manoeuvre(self.n_states, names)
        codes = None if labels is None else labels.codes(names)
        inputs = read_joint_inputs(self, X, y, groups, time, fitting=True)
        standardized, scaling, stale_noise = self._standardized(inputs, sum(sizes))
        settings = HierarchyEM(
            start=self.start,
            refine_iter=self.refine_iter,
            n_iter=self.n_iter,
            tol=self.tol,
            n_init=self.n_init,
            init_params=self.init_params,
            reg_covar=self.reg_covar,
            covariance_type=self.covariance_type,
        )
        result, sizes = settings.fit(
            standardized, inputs.recordings, codes, names, sizes, self.random_state
        )
        self._set_structure(names, sizes)
        # with labels, refine_iter is a budget of refinement, not a fit to convergence
        if not result.converged and codes is None:
            warnings.warn(
                f"the joint EM did not converge in n_iter={self.n_iter} iterations "
                f"(tol={self.tol}); increase n_iter or tol.",
                ConvergenceWarning,
                stacklevel=2,
            )
        self._set_fitted(result, inputs, scaling, stale_noise)
        return self

    def fit_transform(self, X, y, groups=None, time=None, manoeuvre=None):
        """Fit, then return the filtered state probabilities of the training recordings."""
        self.fit(X, y, groups=groups, time=time, manoeuvre=manoeuvre)
        return self.transform(X, groups=groups, time=time)

    # -- read-outs ------------------------------------------------------------------------------
    def predict_manoeuvre_proba(self, X, groups=None, time=None):
        """Filtered probability of every manoeuvre given the inputs up to each row.

        The sum of the filtered probabilities of the manoeuvre's states
        (:meth:`predict_state_proba`), causal like :meth:`predict`.

        Parameters
        ----------
        X : array-like of shape (n_samples, n_features)
        groups : array-like of shape (n_samples,), default=None
            Recording id of every row; the filter restarts at every recording.
        time : array-like of shape (n_samples,), default=None
            Optional time stamps, checked to increase within every recording.

        Returns
        -------
        proba : ndarray of shape (n_samples, n_manoeuvres)
            Columns in the order of ``manoeuvres_``; rows sum to one.
        """
        alpha = self.predict_state_proba(X, groups=groups, time=time)
        return self._hierarchy().per_manoeuvre(alpha)

    def _parts(self):
        check_is_fitted(self)
        return self._hierarchy().decompose(self.model_.transmat)

    @property
    def manoeuvre_transmat_(self):
        return self._parts().chain

    @property
    def exit_proba_(self):
        return self._parts().exit

    @property
    def entry_proba_(self):
        return self._parts().entry

    @property
    def manoeuvre_startprob_(self):
        check_is_fitted(self)
        return self._hierarchy().per_manoeuvre(self.model_.startprob)

    def get_feature_names_out(self, input_features=None):
        """Names of the state-probability columns: ``state_0`` ... (all manoeuvres' states)."""
        check_is_fitted(self)
        return np.asarray([f"state_{k}" for k in range(self.model_.n_states)], dtype=object)

    def n_parameters(self):
        """Free parameters of the fitted hierarchy (for information criteria): start
        probabilities, every manoeuvre's transitions, exits, chain and entries, and the
        state densities."""
        check_is_fitted(self)
        transitions = self._hierarchy().n_transition_parameters()
        return int(transitions + self.model_.emissions.n_parameters())

    # -- model files ----------------------------------------------------------------------------
    @classmethod
    def from_fitted_model(cls, model, **params):
        """A fitted estimator around a :class:`~skhmmgmr.FittedHMMGMR` whose states are the
        manoeuvres' blocks in order.

        Parameters
        ----------
        model : FittedHMMGMR
        **params : dict
            Estimator parameters; ``manoeuvres`` (a number or names, not None) and
            ``n_states`` must give the model's number of states.

        Returns
        -------
        estimator : HierarchicalHMMGMRRegressor
        """
        given = cls(**params)
        estimator = super().from_fitted_model(model, **params)  # validates the parameters
        estimator.n_states = given.n_states
        names = _manoeuvre_names(estimator.manoeuvres)
        sizes = _states_per_manoeuvre(estimator.n_states, names)
        if sum(sizes) != model.n_states:
            raise ValueError(
                f"the model has {model.n_states} states; manoeuvres={names} with "
                f"n_states={sizes} make {sum(sizes)}"
            )
        for attribute, value in _structure_attributes(names, sizes).items():
            setattr(estimator, attribute, value)
        return estimator

    def __skhmmgmr_file_params__(self):
        """The parameters the model file keeps: the fitted manoeuvres' names and states
        (``manoeuvres`` and ``n_states`` as lists), so that loading restores the hierarchy."""
        params = super().__skhmmgmr_file_params__()
        params["manoeuvres"] = [_plain(name) for name in self.manoeuvres_]
        params["n_states"] = [int(size) for size in self.states_per_manoeuvre_]
        return params


def _manoeuvre_names(manoeuvres, labels=None):
    """The manoeuvres' names from the parameter ``manoeuvres`` (or, for None, the
    :class:`_Labels` of fit)."""
    if manoeuvres is None:
        if labels is None:
            raise ValueError(
                "manoeuvres=None takes the manoeuvres from the labels: pass "
                "manoeuvre=<label per row> to fit, or give manoeuvres (a number or names)"
            )
        return labels.names()
    if isinstance(manoeuvres, Integral):
        return list(range(int(manoeuvres)))
    if isinstance(manoeuvres, Mapping | Set):
        raise InvalidParameterError(
            "The 'manoeuvres' parameter of HierarchicalHMMGMRRegressor must be a number of "
            f"manoeuvres, a list of their names in the order of their blocks, or None; got the "
            f"{type(manoeuvres).__name__} {manoeuvres!r} (the states per manoeuvre go in "
            "n_states, which takes a dict)"
        )
    names = [_plain(name) for name in np.asarray(manoeuvres, dtype=object).ravel()]
    if not names:
        raise ValueError("manoeuvres is an empty list; give at least one manoeuvre")
    for name in names:
        if not _is_label(name):
            raise ValueError(
                f"manoeuvres holds {name!r}: every manoeuvre's name must be a text or a number"
            )
    if len(set(names)) != len(names):
        twice = sorted({str(n) for n in names if names.count(n) > 1})
        raise ValueError(f"manoeuvres names {twice} more than once")
    return names


def _states_per_manoeuvre(n_states, names):
    """States per manoeuvre from the parameter ``n_states``, in the order of ``names``."""
    if isinstance(n_states, Mapping):
        given = {_plain(key): value for key, value in n_states.items()}
        missing = [name for name in names if name not in given]
        unknown = [key for key in given if key not in names]
        if missing or unknown:
            raise ValueError(
                f"n_states must give the states of every manoeuvre {names}: "
                + (f"it misses {missing}" if missing else f"it names unknown {unknown}")
            )
        sizes = [given[name] for name in names]
    elif isinstance(n_states, Integral):
        sizes = [n_states] * len(names)
    else:
        sizes = list(np.asarray(n_states, dtype=object).ravel())
        if len(sizes) != len(names):
            raise ValueError(
                f"n_states has {len(sizes)} values for {len(names)} manoeuvres {names}"
            )
    for name, size in zip(names, sizes, strict=True):
        if isinstance(size, bool) or not isinstance(size, Integral) or size < 1:
            raise ValueError(
                f"n_states of manoeuvre {name!r} must be a whole number >= 1, got {size!r}"
            )
    return [int(size) for size in sizes]


def _structure_attributes(names, sizes):
    """The fitted attributes that say the manoeuvres' blocks of states."""
    return {
        "manoeuvres_": np.asarray(names, dtype=object),
        "states_per_manoeuvre_": np.asarray(sizes, dtype=int),
        "state_manoeuvre_": Hierarchy(sizes).state_manoeuvre.copy(),
    }


def _plain(value):
    """A label as a Python scalar (NumPy strings and integers compare and print plainly)."""
    return value.item() if isinstance(value, np.generic) else value


def _is_label(value):
    """Whether ``value`` may name a manoeuvre: a text or a number, not missing (None, NaN)."""
    return isinstance(value, str | Number) and value == value


class _Labels:
    """The manoeuvre label of every row, in the filter order of fit, and where every row came
    from (its row in ``X`` and its recording), to name them in errors."""

    def __init__(self, labels, rows, recordings):
        self.labels, self.rows, self.recordings = labels, rows, recordings

    @classmethod
    def read(cls, manoeuvre, X, groups, time):
        labels = np.asarray(manoeuvre, dtype=object).ravel()
        n_rows = _n_rows(X)
        if labels.shape[0] != n_rows:
            raise ValueError(
                f"manoeuvre has {labels.shape[0]} labels, X has {n_rows} rows: give one "
                "manoeuvre label per row"
            )
        layout = read_layout(X, groups, time, canonical=True)
        rows = np.arange(n_rows) if layout.order is None else np.asarray(layout.order)
        read = cls(layout.to_filter_order(labels), rows, layout.groups)
        plain = [_plain(label) for label in read.labels]
        bad = next((i for i, label in enumerate(plain) if not _is_label(label)), None)
        if bad is not None:
            raise ValueError(
                f"manoeuvre holds {plain[bad]!r} at {read.where(bad)}: every row needs the "
                "name (a text or a number) of its manoeuvre"
            )
        read.labels = plain
        return read

    def where(self, i):
        """Row ``i`` (filter order) named by its row in ``X`` and its recording."""
        row = f"row {self.rows[i]} of X"
        if self.recordings is None:
            return row
        return f"{row} (recording {_plain(self.recordings[i])!r})"

    def names(self):
        """The distinct labels, sorted (``manoeuvres=None``)."""
        try:
            return [_plain(name) for name in np.unique(np.asarray(self.labels, dtype=object))]
        except TypeError:  # texts and numbers do not sort together
            kinds = sorted({type(label).__name__ for label in self.labels})
            raise ValueError(
                f"manoeuvre mixes labels of the types {kinds}, which have no order: give "
                "manoeuvres=[...] to name the manoeuvres in the order of their blocks"
            ) from None

    def codes(self, names):
        """The manoeuvre index of every row; a label not among ``names`` refused."""
        index = {name: i for i, name in enumerate(names)}
        unknown = sorted({str(label) for label in self.labels if label not in index})
        if unknown:
            first = next(i for i, label in enumerate(self.labels) if label not in index)
            raise ValueError(
                f"manoeuvre holds the label(s) {unknown}, not among manoeuvres={names}; the "
                f"first is at {self.where(first)}"
            )
        return np.fromiter((index[v] for v in self.labels), dtype=np.intp, count=len(self.labels))


def _n_rows(X):
    return X.shape[0] if hasattr(X, "shape") else len(X)
