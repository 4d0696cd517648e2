"""The HMM-GMR engine: compiled kernels, Gaussian algebra, emission models, EM, GMR filter.

Layered by stage: ``_kernels`` (compiled recursions over scaled likelihoods) < ``_gaussian``
(moments, Cholesky factors, log-densities) < ``_emissions`` (the state densities' form) <
``_em_data``/``_em_init``/``_fused_estep``/``_em`` (Baum-Welch) < ``_fitted``/``_gmr`` (the
fitted state and its causal read-out); ``_missing`` and ``_stale_inputs`` condition on the
observed inputs, ``_hmmlearn`` converts to and from hmmlearn. Private: import the public names
from ``skhmmgmr``.
"""
