"""The torque pipeline: the derived inputs of a power-assisted steering system
(:class:`SteeringFeatures`) in front of :class:`~skhmmgmr.HMMGMRRegressor`, as a
scikit-learn ``Pipeline`` whose recordings reach every step (:class:`TorquePipeline`,
:func:`make_torque_pipeline`)."""

# the filter and the candidates of the "auto" choice, at the path they had as one module
from ._derived_inputs import low_pass as low_pass
from ._friction_search import FILTER_CANDIDATES as FILTER_CANDIDATES
from ._friction_search import WIDTH_GRID as WIDTH_GRID
from ._pipeline import TorquePipeline, make_torque_pipeline
from ._steering_features import SteeringFeatures

__all__ = ["SteeringFeatures", "TorquePipeline", "make_torque_pipeline"]
