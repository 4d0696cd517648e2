"""Manoeuvres as a hierarchy: one HMM-GMR per manoeuvre, sequenced by a Markov chain.

The two levels are fitted and kept as one flat HMM-GMR whose transition matrix has the block
structure of :mod:`skhmmgmr._hmm._hierarchy`; the regressor's causal filter, ``predict``
with ``return_std``, the streaming filter, the model file and the C export read that flat
model as they read any other.
"""

import warnings
from collections.abc import Mapping
from numbers import Integral

import numpy as np
from sklearn.cluster import KMeans
from sklearn.exceptions import ConvergenceWarning
from sklearn.utils import check_random_state
from sklearn.utils.validation import check_is_fitted

from .._core._compat import Interval, StrOptions, _fit_context
from .._core._panel import read_layout
from .._core._sequences import Recordings
from .._hmm._em import (
    EMResult,
    HMMParameters,
    e_step,
    fit_hmm,
    score_hmm,
    state_posteriors,
)
from .._hmm._em_data import Columns, EStepData
from .._hmm._emissions import GaussianEmissions, emission_family
from .._hmm._hierarchy import Hierarchy, HierarchyParts
from .._hmm._portable import HIERARCHICAL_TYPE
from ._prediction_inputs import read_joint_inputs
from ._regressor import HMMGMRRegressor

# Pseudo-count added to every count of the label sequence (manoeuvre starts, exits, chain
# transitions): a manoeuvre change the labels never show keeps a small probability, which the
# joint refinement can raise.
PSEUDO_COUNT = 0.5


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
    output_smoothing : None, float >= 0 or "auto", default=None
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
    _portable_type = HIERARCHICAL_TYPE

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
        labels = None
        if manoeuvre is not None:
            labels = np.asarray(manoeuvre, dtype=object).ravel()
            if labels.shape[0] != _n_rows(X):
                raise ValueError(
                    f"manoeuvre has {labels.shape[0]} labels, X has {_n_rows(X)} rows: give "
                    "one manoeuvre label per row"
                )
        names = _manoeuvre_names(self.manoeuvres, labels)
        sizes = _states_per_manoeuvre(self.n_states, names)
        codes = None if labels is None else _codes(labels, names, X, groups, time)
        inputs = read_joint_inputs(self, X, y, groups, time, fitting=True)
        self._set_structure(names, sizes)
        hierarchy = self._hierarchy()
        standardized, scaling, stale_noise = self._standardized(inputs, hierarchy.n_states)
        recordings = inputs.recordings
        result = self._fit_hierarchy(standardized, recordings, codes, hierarchy)
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

    def _fit_hierarchy(self, columns, recordings, codes, hierarchy):
        """The EM result of the flat hierarchical HMM on the standardised ``columns`` (with
        ``start="flat"``, the structure is set again to the sizes the flat model gave)."""
        rng = check_random_state(self.random_state)
        if codes is not None:
            start, hierarchy = self._start(columns, recordings, codes, hierarchy, rng)
            return self._joint_em(columns, recordings, start, hierarchy, self.refine_iter)
        best = None
        for _ in range(self.n_init):
            codes = self._kmeans_codes(columns, hierarchy.n_manoeuvres, rng)
            start, found = self._start(columns, recordings, codes, hierarchy, rng)
            result = self._joint_em(columns, recordings, start, found, self.n_iter)
            if best is None or result.objective > best.objective:
                best, sizes = result, found.sizes
        self._set_structure(list(self.manoeuvres_), sizes)
        return best

    def _start(self, columns, recordings, codes, hierarchy, rng):
        """``(parameters, hierarchy)`` the joint EM starts from (see ``start``)."""
        if self.start == "labels":
            return self._labelled_start(columns, recordings, codes, hierarchy, rng), hierarchy
        parameters, sizes = self._flat_start(columns, recordings, codes, hierarchy, rng)
        self._set_structure(list(self.manoeuvres_), sizes)
        return parameters, self._hierarchy()

    def _flat_start(self, columns, recordings, codes, hierarchy, rng):
        """The flat HMM of as many states, every state given to the manoeuvre whose rows hold
        most of its posterior probability (every manoeuvre at least one state, taken from
        the manoeuvre with the most states where it has the largest share), the states
        ordered by manoeuvre and the transitions of the hierarchy estimated from them (one
        M-step of the parts). Returns ``(parameters, sizes)``."""
        n_manoeuvres, total = hierarchy.n_manoeuvres, hierarchy.n_states
        flat = self._fit_states(columns, recordings, total, rng).parameters
        posteriors = state_posteriors(_copy(columns), recordings, flat)
        mass = np.zeros((n_manoeuvres, total))
        np.add.at(mass, codes, posteriors)
        owner = mass.argmax(axis=0)
        for m in range(n_manoeuvres):
            if np.any(owner == m):
                continue
            counts = np.bincount(owner, minlength=n_manoeuvres)
            free = np.flatnonzero(counts[owner] > 1)
            share = mass[m, free] / np.maximum(mass[:, free].sum(axis=0), np.finfo(float).tiny)
            owner[free[np.argmax(share)]] = m
        order = np.argsort(owner, kind="stable")
        sizes = np.bincount(owner, minlength=n_manoeuvres)
        permuted = HMMParameters(
            flat.startprob[order],
            flat.transmat[np.ix_(order, order)],
            flat.emissions.reordered(order),
        )
        structure = Hierarchy(sizes)
        stats = e_step(EStepData(_copy(columns), recordings, total), permuted)
        startprob, transmat = structure.maximize(
            stats.start_counts, stats.transition_counts, permuted
        )
        return HMMParameters(startprob, transmat, permuted.emissions), sizes

    def _fit_states(self, columns, recordings, n_states, rng):
        """An unstructured HMM of ``n_states`` on ``columns``, with the estimator's EM
        settings (the :class:`EMResult`)."""
        return fit_hmm(
            columns,
            recordings,
            n_states,
            n_init=self.n_init,
            init_params=self.init_params,
            n_iter=self.n_iter,
            tol=self.tol,
            reg_covar=self.reg_covar,
            random_state=rng,
            covariance_type=self.covariance_type,
        )

    def _joint_em(self, columns, recordings, start, hierarchy, n_iter):
        if n_iter == 0:
            prior = type(start.emissions).prior_for(
                self.reg_covar, columns.n_samples, hierarchy.n_states
            )
            log_likelihood = score_hmm(
                Columns(columns.values.copy(), columns.shift), recordings, start
            )
            objective = log_likelihood + start.emissions.log_prior(prior)
            return EMResult(start, log_likelihood, [log_likelihood], 0, True, objective)
        return fit_hmm(
            columns,
            recordings,
            hierarchy.n_states,
            n_iter=n_iter,
            tol=self.tol,
            reg_covar=self.reg_covar,
            initial_parameters=start,
            covariance_type=self.covariance_type,
            transitions=hierarchy,
        )

    @staticmethod
    def _kmeans_codes(columns, n_manoeuvres, rng):
        """A manoeuvre per row by k-means on the standardised rows (missing values at their
        column's mean)."""
        if n_manoeuvres == 1:
            return np.zeros(columns.n_samples, dtype=np.intp)
        rows = np.nan_to_num(columns.rows())
        kmeans = KMeans(n_manoeuvres, n_init=1, random_state=rng.randint(2**31 - 1))
        return kmeans.fit_predict(rows).astype(np.intp)

    def _labelled_start(self, columns, recordings, codes, hierarchy, rng):
        """The flat HMM read from the labels: every manoeuvre's HMM fitted on its segments,
        the chain, exits and starts counted on the label sequence."""
        segments = _segments(codes, recordings)
        names = self.manoeuvres_
        n_manoeuvres = hierarchy.n_manoeuvres
        starts, stops, seg_codes, follows = segments
        blocks, weights = [], []
        within = np.zeros((hierarchy.n_states, hierarchy.n_states))
        entry = np.empty(hierarchy.n_states)
        exit = np.zeros(hierarchy.n_states)
        for m in range(n_manoeuvres):
            mine = np.flatnonzero(seg_codes == m)
            lengths = stops[mine] - starts[mine]
            n_rows, size = int(lengths.sum()), hierarchy.sizes[m]
            if n_rows < size:
                raise ValueError(
                    f"manoeuvre {names[m]!r} has {n_rows} row(s), fewer than its {size} "
                    "state(s): every state needs at least one row (label more rows of it, or "
                    "give it fewer states in n_states)"
                )
            rows = np.flatnonzero(codes == m)  # its segments, in order
            bounds = np.concatenate([[0], np.cumsum(lengths)])
            block = Recordings(ids=np.arange(len(mine)), starts=bounds[:-1], stops=bounds[1:])
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", ConvergenceWarning)
                rows_of_m = Columns(columns.values[:, rows], columns.shift)
                result = self._fit_states(rows_of_m, block, size, rng)
            params = result.parameters
            span = hierarchy.block(m)
            within[span, span] = params.transmat
            entry[span] = params.startprob
            # leaving: the segments followed by another manoeuvre in their recording
            exit[span] = (np.sum(follows[mine] >= 0) + PSEUDO_COUNT) / (n_rows + 1.0)
            blocks.append(params.emissions)
            weights.append(n_rows)
        chain = np.full((n_manoeuvres, n_manoeuvres), PSEUDO_COUNT)
        changes = follows >= 0
        np.add.at(chain, (seg_codes[changes], follows[changes]), 1.0)
        np.fill_diagonal(chain, 0.0)
        if n_manoeuvres == 1:
            exit[:] = 0.0
        else:
            chain /= chain.sum(axis=1, keepdims=True)
        first = np.full(n_manoeuvres, PSEUDO_COUNT)
        np.add.at(first, codes[recordings.starts], 1.0)
        first /= first.sum()
        startprob = first[hierarchy.state_manoeuvre] * entry
        transmat = hierarchy.compose(HierarchyParts(within, exit, chain, entry))
        emissions = GaussianEmissions.stacked(blocks, weights)
        return HMMParameters(startprob / startprob.sum(), transmat, emissions)

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

    def to_dict(self, *, output_names=None):
        """The fitted model as a JSON-ready dict (the portable model format).

        As :meth:`HMMGMRRegressor.to_dict`, with the fitted manoeuvres' names and states in
        ``estimator_params`` (``manoeuvres`` and ``n_states`` as lists), so that
        :meth:`from_dict` restores the hierarchy.
        """
        data = super().to_dict(output_names=output_names)
        data["estimator_params"]["manoeuvres"] = [_plain(name) for name in self.manoeuvres_]
        data["estimator_params"]["n_states"] = [int(size) for size in self.states_per_manoeuvre_]
        return data


def _manoeuvre_names(manoeuvres, labels=None):
    """The manoeuvres' names from the parameter ``manoeuvres`` (or, for None, the labels)."""
    if manoeuvres is None:
        if labels is None:
            raise ValueError(
                "manoeuvres=None takes the manoeuvres from the labels: pass "
                "manoeuvre=<label per row> to fit, or give manoeuvres (a number or names)"
            )
        return [_plain(name) for name in np.unique(labels)]
    if isinstance(manoeuvres, Integral):
        return list(range(int(manoeuvres)))
    names = [_plain(name) for name in np.asarray(manoeuvres, dtype=object).ravel()]
    if not names:
        raise ValueError("manoeuvres is an empty list; give at least one manoeuvre")
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


def _codes(labels, names, X, groups, time):
    """The manoeuvre index of every row, in the filter order of fit; unknown labels
    refused."""
    labels = read_layout(X, groups, time, canonical=True).to_filter_order(labels)
    index = {name: i for i, name in enumerate(names)}
    unknown = sorted({str(label) for label in labels if _plain(label) not in index})
    if unknown:
        raise ValueError(f"manoeuvre holds the label(s) {unknown}, not among manoeuvres={names}")
    return np.fromiter((index[_plain(v)] for v in labels), dtype=np.intp, count=len(labels))


def _copy(columns):
    """Columns the engine may change in place (it zeroes missing values)."""
    return Columns(columns.values.copy(), columns.shift)


def _n_rows(X):
    return X.shape[0] if hasattr(X, "shape") else len(X)


def _segments(codes, recordings):
    """``(starts, stops, codes, follows)`` of the runs of one manoeuvre within every
    recording; ``follows`` is the manoeuvre of the next run in the same recording, or -1."""
    n_samples = codes.shape[0]
    breaks = np.zeros(n_samples, dtype=bool)
    breaks[np.asarray(recordings.starts, dtype=int)] = True
    breaks[1:] |= codes[1:] != codes[:-1]
    starts = np.flatnonzero(breaks)
    stops = np.append(starts[1:], n_samples)
    seg_codes = codes[starts]
    follows = np.full(starts.shape[0], -1, dtype=np.intp)
    recording_start = np.zeros(n_samples, dtype=bool)
    recording_start[np.asarray(recordings.starts, dtype=int)] = True
    same_recording = np.append(~recording_start[stops[:-1]], False)
    follows[same_recording] = seg_codes[1:][same_recording[:-1]]
    return starts, stops, seg_codes, follows
