"""Manoeuvres as a two-level hierarchy of hidden states, flattened into one HMM.

Every manoeuvre ``m`` owns a block of ``K_m`` consecutive states (its own HMM); a Markov chain
sequences the manoeuvres (thesis Appendix E.3, after Pentland and Liu). The two levels are
written as one transition matrix over all ``K = sum K_m`` states, whose blocks are

- within manoeuvre ``m``: ``A[(m, i), (m, j)] = (1 - x_mi) B_m[i, j]``, with ``B_m`` the
  manoeuvre's own transition matrix and ``x_mi`` the probability of leaving the manoeuvre
  from its state ``i`` (its exit probability);
- from manoeuvre ``m`` to another ``n``: ``A[(m, i), (n, j)] = x_mi C[m, n] e_n[j]``, with
  ``C`` the chain over manoeuvres (zero diagonal: staying is the within-block part) and
  ``e_n`` the entry distribution of manoeuvre ``n`` over its states.

The start probabilities are free over all states. The causal filter of the flat HMM is then
exactly the two-level filter, and the probability of a manoeuvre is the sum of its states'.

:class:`Hierarchy` composes the flat matrix from the parts, reads the parts back, and is the
exact M-step of the parts for the EM engine (:func:`~skhmmgmr._hmm._em.m_step`): the expected
log-likelihood of the transitions splits into one multinomial per part, so that each part is
its expected counts, normalised.
"""

from dataclasses import dataclass

import numpy as np

from ._em import PROBABILITY_FLOOR


@dataclass(frozen=True)
class HierarchyParts:
    """The parts of a block-structured transition matrix (see the module docstring).

    Attributes
    ----------
    within : ndarray of shape (n_states, n_states)
        Block diagonal: ``B_m`` in the block of manoeuvre ``m``, rows summing to one.
    exit : ndarray of shape (n_states,)
        Probability of leaving the state's manoeuvre (zero with one manoeuvre).
    chain : ndarray of shape (n_manoeuvres, n_manoeuvres)
        Transitions between manoeuvres; zero diagonal, rows summing to one (a zero row with
        one manoeuvre).
    entry : ndarray of shape (n_states,)
        Entry distribution of every manoeuvre over its states (sums to one per block).
    """

    within: np.ndarray
    exit: np.ndarray
    chain: np.ndarray
    entry: np.ndarray


def _normalized(counts, previous):
    """``counts`` over their sum along the last axis, floored; ``previous`` where none."""
    totals = counts.sum(axis=-1, keepdims=True)
    result = np.where(totals > 0, counts / np.where(totals > 0, totals, 1.0), previous)
    result = np.maximum(result, PROBABILITY_FLOOR)
    return result / result.sum(axis=-1, keepdims=True)


class Hierarchy:
    """Block structure of ``sizes[m]`` states per manoeuvre, in order."""

    def __init__(self, sizes):
        self.sizes = tuple(int(size) for size in sizes)
        self.bounds = np.concatenate([[0], np.cumsum(self.sizes)]).astype(int)
        self.state_manoeuvre = np.repeat(np.arange(len(self.sizes)), self.sizes)

    @property
    def n_manoeuvres(self):
        return len(self.sizes)

    @property
    def n_states(self):
        return int(self.bounds[-1])

    def block(self, m):
        return slice(int(self.bounds[m]), int(self.bounds[m + 1]))

    def same_manoeuvre(self):
        """Boolean (n_states, n_states): whether two states belong to one manoeuvre."""
        return self.state_manoeuvre[:, np.newaxis] == self.state_manoeuvre[np.newaxis, :]

    def per_manoeuvre(self, values):
        """Sums of the last axis of ``values`` (one value per state) per manoeuvre."""
        values = np.asarray(values, dtype=float)
        return np.add.reduceat(values, self.bounds[:-1], axis=-1)

    def compose(self, parts):
        """The flat transition matrix of ``parts`` (:class:`HierarchyParts`)."""
        m_of = self.state_manoeuvre
        between = parts.exit[:, np.newaxis] * parts.chain[m_of][:, m_of] * parts.entry
        stay = (1.0 - parts.exit)[:, np.newaxis] * parts.within
        return np.where(self.same_manoeuvre(), stay, between)

    def decompose(self, transmat):
        """The :class:`HierarchyParts` of a flat transition matrix (its blocks' structure
        assumed: the inverse of :meth:`compose`)."""
        transmat = np.asarray(transmat, dtype=float)
        same = self.same_manoeuvre()
        inside = np.where(same, transmat, 0.0)
        stay = inside.sum(axis=1)
        within = inside / np.where(stay > 0, stay, 1.0)[:, np.newaxis]
        n_manoeuvres = self.n_manoeuvres
        if n_manoeuvres == 1:
            return HierarchyParts(
                within,
                np.zeros(self.n_states),
                np.zeros((1, 1)),
                np.full(self.n_states, 1.0 / self.n_states),
            )
        exit = np.clip(1.0 - stay, 0.0, 1.0)
        chain = np.zeros((n_manoeuvres, n_manoeuvres))
        entry = np.zeros(self.n_states)
        entry_weight = np.zeros(n_manoeuvres)
        for m in range(n_manoeuvres):
            rows = self.block(m)
            # the state most likely to leave reads the chain and the entries with the least
            # round-off (the parts are the same from every state of the block)
            i = rows.start + int(np.argmax(exit[rows]))
            to_manoeuvre = self.per_manoeuvre(transmat[i])
            to_manoeuvre[m] = 0.0
            chain[m] = to_manoeuvre / max(to_manoeuvre.sum(), np.finfo(float).tiny)
            for n in range(n_manoeuvres):
                if n != m and to_manoeuvre[n] > entry_weight[n]:
                    entry_weight[n] = to_manoeuvre[n]
                    entry[self.block(n)] = transmat[i, self.block(n)] / to_manoeuvre[n]
        return HierarchyParts(within, exit, chain, entry)

    def maximize(self, start_counts, transition_counts, previous):
        """The M-step of the start probabilities and the parts, from the expected counts of
        an E-step (``previous``: the HMM parameters in force, whose parts stay where there is
        no count). Returns ``(startprob, transmat)``."""
        startprob = _normalized(start_counts, previous.startprob)
        old = self.decompose(previous.transmat)
        counts = np.asarray(transition_counts, dtype=float)
        same = self.same_manoeuvre()
        inside = np.where(same, counts, 0.0)
        within = _normalized(inside, old.within)
        within = np.where(same, within, 0.0)  # the floor applies inside the blocks only
        within /= within.sum(axis=1, keepdims=True)
        if self.n_manoeuvres == 1:
            return startprob, within
        outside = np.where(same, 0.0, counts)
        leave = outside.sum(axis=1)
        total = leave + inside.sum(axis=1)
        exit = np.where(total > 0, leave / np.where(total > 0, total, 1.0), old.exit)
        exit = np.clip(exit, PROBABILITY_FLOOR, 1.0 - np.finfo(float).eps)
        between = self.per_manoeuvre(self.per_manoeuvre(outside.T).T)  # (m, n) counts
        np.fill_diagonal(between, 0.0)
        chain = _normalized(between, old.chain)
        np.fill_diagonal(chain, 0.0)
        chain /= chain.sum(axis=1, keepdims=True)
        arrivals = outside.sum(axis=0)
        entry = np.empty(self.n_states)
        for m in range(self.n_manoeuvres):
            rows = self.block(m)
            entry[rows] = _normalized(arrivals[rows], old.entry[rows])
        parts = HierarchyParts(within, exit, chain, entry)
        return startprob, self.compose(parts)

    def n_transition_parameters(self):
        """Free start and transition probabilities of the hierarchy."""
        n_states, n_manoeuvres = self.n_states, self.n_manoeuvres
        within = sum(size * (size - 1) for size in self.sizes)
        if n_manoeuvres == 1:
            return (n_states - 1) + within
        chain = n_manoeuvres * (n_manoeuvres - 2)
        entries = n_states - n_manoeuvres
        return (n_states - 1) + within + n_states + chain + entries
