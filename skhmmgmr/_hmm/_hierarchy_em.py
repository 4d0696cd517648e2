"""The manoeuvre hierarchy fitted by EM: where the joint EM starts, and the joint EM.

The hierarchy is one flat HMM whose transition matrix keeps the block structure of
:mod:`._hierarchy`; the engine (:func:`~._em.fit_hmm` with ``transitions=``) runs its EM. What
is particular to the hierarchy is the start:

- ``"labels"``: with a manoeuvre label per row, every manoeuvre's HMM is fitted on its
  segments (the runs of rows of one label within a recording), and the chain over manoeuvres,
  the exit, entry and start probabilities are counted on the label sequence, with a
  pseudo-count;
- ``"flat"``: an unstructured HMM of as many states in total is fitted, every state given to
  the manoeuvre whose rows hold most of its posterior probability, and the hierarchy's
  transitions estimated from its expected transitions (one M-step of the parts);
- without labels, the labels are first drawn by k-means on the standardised rows (one cluster
  per manoeuvre), ``n_init`` times, and the joint EM of the best objective is kept.

:class:`HierarchyEM` holds the estimator's EM settings; its :meth:`~HierarchyEM.fit` returns
the EM result and the states per manoeuvre (which the flat start may change).
"""

import warnings
from dataclasses import dataclass

import numpy as np
from sklearn.cluster import KMeans
from sklearn.exceptions import ConvergenceWarning
from sklearn.utils import check_random_state

from .._core._sequences import Recordings
from ._em import EMResult, HMMParameters, e_step, fit_hmm, score_hmm, state_posteriors
from ._em_data import Columns, EStepData
from ._emissions import GaussianEmissions
from ._hierarchy import Hierarchy, HierarchyParts

# Pseudo-count added to every count of the label sequence (manoeuvre starts, exits, chain
# transitions): a manoeuvre change the labels never show keeps a small probability, which the
# joint refinement can raise.
PSEUDO_COUNT = 0.5


@dataclass(frozen=True)
class HierarchyEM:
    """The EM settings of a hierarchical fit (the estimator's parameters of the same names).

    Attributes
    ----------
    start : {"labels", "flat"}
        Where the joint EM starts (see the module docstring).
    refine_iter : int
        Iterations of the joint EM after a start read from labels (0: the start itself).
    n_iter : int
        Iterations of every unstructured fit, and of the joint EM without labels.
    tol, n_init, init_params, reg_covar, covariance_type
        As in :func:`~._em.fit_hmm`.
    """

    start: str
    refine_iter: int
    n_iter: int
    tol: float
    n_init: int
    init_params: str
    reg_covar: float
    covariance_type: str

    def fit(self, columns, recordings, codes, names, sizes, random_state):
        """Fit the hierarchy on the standardised ``columns``.

        Parameters
        ----------
        columns : Columns
        recordings : Recordings
        codes : ndarray of int of shape (n_samples,) or None
            The manoeuvre index of every row, in filter order; None: found by k-means.
        names : list
            The manoeuvres' names, for the errors.
        sizes : sequence of int
            States per manoeuvre.
        random_state : int, RandomState instance or None

        Returns
        -------
        result : EMResult
        sizes : tuple of int
            States per manoeuvre of the result (``start="flat"`` may move states).
        """
        rng = check_random_state(random_state)
        hierarchy = Hierarchy(sizes)
        if codes is not None:
            start, hierarchy = self._start(columns, recordings, codes, names, hierarchy, rng)
            result = self._joint_em(columns, recordings, start, hierarchy, self.refine_iter)
            return result, hierarchy.sizes
        best = None
        for _ in range(self.n_init):
            codes = kmeans_codes(columns, hierarchy.n_manoeuvres, rng)
            start, found = self._start(columns, recordings, codes, names, hierarchy, rng)
            result = self._joint_em(columns, recordings, start, found, self.n_iter)
            if best is None or result.objective > best.objective:
                best, best_sizes = result, found.sizes
        return best, best_sizes

    def _start(self, columns, recordings, codes, names, hierarchy, rng):
        """``(parameters, hierarchy)`` the joint EM starts from (see ``start``)."""
        if self.start == "labels":
            start = self._labelled_start(columns, recordings, codes, names, hierarchy, rng)
            return start, hierarchy
        parameters, sizes = self._flat_start(columns, recordings, codes, hierarchy, rng)
        return parameters, Hierarchy(sizes)

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
        """An unstructured HMM of ``n_states`` on ``columns`` (the :class:`EMResult`)."""
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
            log_likelihood = score_hmm(_copy(columns), recordings, start)
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

    def _labelled_start(self, columns, recordings, codes, names, hierarchy, rng):
        """The flat HMM read from the labels: every manoeuvre's HMM fitted on its segments,
        the chain, exits and starts counted on the label sequence."""
        starts, stops, seg_codes, follows = segments(codes, recordings)
        n_manoeuvres = hierarchy.n_manoeuvres
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


def kmeans_codes(columns, n_manoeuvres, rng):
    """A manoeuvre per row by k-means on the standardised rows (missing values at their
    column's mean)."""
    if n_manoeuvres == 1:
        return np.zeros(columns.n_samples, dtype=np.intp)
    rows = np.nan_to_num(columns.rows())
    kmeans = KMeans(n_manoeuvres, n_init=1, random_state=rng.randint(2**31 - 1))
    return kmeans.fit_predict(rows).astype(np.intp)


def segments(codes, recordings):
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


def _copy(columns):
    """Columns the engine may change in place (it zeroes missing values)."""
    return Columns(columns.values.copy(), columns.shift)
