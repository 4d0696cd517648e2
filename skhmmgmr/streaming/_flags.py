"""What an update of a :class:`~skhmmgmr.FilterStream` did with its sample: the flags.

``"ok"`` and ``"restarted"`` (the transitions allowed no state that explains the sample, so the
filter restarted from the input densities, as ``predict`` does) and ``"missing"`` (some inputs
were NaN and marginalised) are accepted samples; ``"non-finite"`` and ``"outlier"`` are held
(:mod:`skhmmgmr._hmm._holds`, the outlier policy that ``predict`` and the generated C share).
"""

FLAG_OK = "ok"
FLAG_NON_FINITE = "non-finite"
FLAG_OUTLIER = "outlier"
FLAG_RESTARTED = "restarted"
FLAG_MISSING = "missing"
HELD_FLAGS = (FLAG_NON_FINITE, FLAG_OUTLIER)
# the samples whose measured outputs an adapting stream learns
LEARNED_FLAGS = (FLAG_OK, FLAG_RESTARTED)
