"""The outlier policy of the causal filter: which samples are held, one rule everywhere.

``predict`` (and the estimator's other read-outs of the filter), :class:`~skhmmgmr.FilterStream`
and the generated C code (:func:`skhmmgmr.export.write_c`, which the FMU wraps) read a sample
of standardised inputs ``z`` by the same rule:

- **filtered**, by default: the forward step works in log space, the input log-density of every
  state taken relative to the best state's before it is exponentiated
  (:func:`~skhmmgmr._hmm._kernels.scaled_densities`), so that no density underflows however
  far the sample lies from the states, and no sample needs holding;
- **out of range**, always: standardised inputs whose absolute values sum to
  :data:`MAX_STANDARDISED` or more, or whose largest input log-density is not finite; the
  model's arithmetic cannot read them (the squares of the density terms would overflow).
  ``predict`` refuses them, naming the row and the column (:func:`check_in_range`), as it
  refuses a NaN or an infinite input; the stream and the C code hold them (flag
  ``"outlier"``, return code 2), as they hold a non-finite input;
- **held**, only when a model's ``min_log_density`` is set: a sample whose largest input
  log-density over the states (standardised units; of its observed inputs when some are
  missing, never a sample with none observed) is below ``min_log_density``. ``predict``, the
  stream and the C code hold the same samples.

A held sample is read as if it had not come: the state probabilities, the read-out and the
estimate keep their values of the last accepted sample of the recording, or before any the
start probabilities and the prior mixture's output mean and std (:meth:`HeldRows.carry`).
"""

from dataclasses import dataclass
from numbers import Real

import numpy as np

from .._core._compat import FiniteInterval, validate_parameter_constraints
from .._core._sequences import Recordings
from .._core._validation import row_location

# Standardised inputs whose absolute values sum to this or more are out of the model's range.
MAX_STANDARDISED = 1e100

# ``min_log_density`` of the estimator and of FilterStream: one constraint, one message.
MIN_LOG_DENSITY_CONSTRAINT = [None, FiniteInterval(Real, None, None, closed="neither")]


def check_min_log_density(value, caller):
    """``value`` as a float, or None; ValueError naming ``min_log_density`` and ``caller`` for
    anything but None and a finite number (NaN would hold every sample, inf every one too)."""
    validate_parameter_constraints(
        {"min_log_density": MIN_LOG_DENSITY_CONSTRAINT},
        {"min_log_density": value},
        caller_name=caller,
    )
    return None if value is None else float(value)


def check_in_range(standardized, *, column_names, recordings, name="X"):
    """Refuse rows of standardised inputs whose absolute values sum to
    :data:`MAX_STANDARDISED` or more (NaN, a missing value, counts as 0), naming the first
    such row, its recording and its largest column."""
    with np.errstate(over="ignore", invalid="ignore"):
        sizes = np.nansum(np.abs(standardized), axis=1)
    beyond = ~(sizes < MAX_STANDARDISED)
    if not beyond.any():
        return
    row = int(np.flatnonzero(beyond)[0])
    column = int(np.nanargmax(np.abs(standardized[row])))
    raise ValueError(
        f"Input {name} is out of the model's range in {row_location(recordings, row)}: its "
        f"inputs, standardised, sum to {sizes[row]:.3g} in absolute value, at most "
        f"{MAX_STANDARDISED:.0e} can be filtered (column {column_names[column]!r} is the "
        f"farthest; {int(beyond.sum())} such row(s) in all). A FilterStream or the generated C "
        "code holds such a sample."
    )


def check_top_finite(top, recordings, name="X"):
    """Refuse rows whose largest input log-density ``top`` is not finite (out of range)."""
    finite = np.isfinite(top)
    if finite.all():
        return
    row = int(np.flatnonzero(~finite)[0])
    raise ValueError(
        f"Input {name} is out of the model's range in {row_location(recordings, row)}: no "
        "state gives its inputs a finite log-density. A FilterStream or the generated C code "
        "holds such a sample."
    )


@dataclass(frozen=True)
class HeldRows:
    """The rows of a batch in filter order that ``min_log_density`` holds, and what every row
    shows: its own values when accepted, those of the last accepted row of its recording
    before it when held (:attr:`source`; -1 before any).

    Attributes
    ----------
    held : ndarray of bool of shape (n_rows,)
    source : ndarray of int of shape (n_rows,)
    accepted : Recordings
        The recordings of the accepted rows alone (positions in ``np.flatnonzero(~held)``),
        over which the recursions and the read-out run.
    """

    held: np.ndarray
    source: np.ndarray
    accepted: Recordings

    @classmethod
    def of(cls, top, recordings, min_log_density, unobserved=None):
        """The held rows of log-densities ``top`` (the largest over the states, per row),
        or None when none is held (``min_log_density`` None, or every row above it).
        ``unobserved``: rows with no input observed, never held."""
        if min_log_density is None:
            return None
        held = top < min_log_density
        if unobserved is not None:
            held[unobserved] = False
        if not held.any():
            return None
        n_rows = held.shape[0]
        positions = np.where(held, -1, np.arange(n_rows))
        last = np.maximum.accumulate(positions)
        # what came before the recording is not its own
        first = np.repeat(recordings.starts, recordings.lengths)
        source = np.where(last >= first, last, -1)
        counts = np.add.reduceat((~held).astype(np.int64), recordings.starts)
        stops = np.cumsum(counts)
        accepted = Recordings(ids=recordings.ids, starts=stops - counts, stops=stops)
        return cls(held, source, accepted)

    @property
    def accepted_rows(self):
        return np.flatnonzero(~self.held)

    def expand(self, accepted_values, before):
        """Per-row values from those of the accepted rows (``accepted_values``, in the order
        of :attr:`accepted_rows`): a held row shows its source's, ``before`` before any."""
        compressed = np.cumsum(~self.held) - 1  # position of each accepted row among them
        values = np.empty((self.held.shape[0], *np.shape(accepted_values)[1:]))
        shown = self.source >= 0
        values[shown] = accepted_values[compressed[self.source[shown]]]
        values[~shown] = before
        return values

    def carry(self, values, before):
        """``values`` (per row, right at the accepted rows) with every held row showing its
        source's, ``before`` before any."""
        return self.expand(values[self.accepted_rows], before)
