"""The HMM-GMR regressor (``HMMGMRRegressor``), with its model files and adaptation, and its
hierarchical form over manoeuvres (``HierarchicalHMMGMRRegressor``)."""

from ._hierarchical import HierarchicalHMMGMRRegressor
from ._regressor import HMMGMRRegressor

__all__ = ["HMMGMRRegressor", "HierarchicalHMMGMRRegressor"]
