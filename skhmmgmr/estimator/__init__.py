"""The HMM-GMR regressor (``HMMGMRRegressor``), with its model files and adaptation."""

from .._core._public import publish
from ._regressor import HMMGMRRegressor

__all__ = ["HMMGMRRegressor"]

publish(globals())
