"""The torque pipeline: the derived inputs of a power-assisted steering system
(:class:`SteeringFeatures`) in front of :class:`~skhmmgmr.HMMGMRRegressor`, as a
scikit-learn ``Pipeline`` whose recordings reach every step (:class:`TorquePipeline`,
:func:`make_torque_pipeline`); the driver model, that pipeline fitted on a perturbation
experiment so that it also drives (:class:`DriverModel`, :func:`make_driver_model`)."""

# the filter and the candidates of the "auto" choice, at the path they had as one module
from ._derived_inputs import low_pass as low_pass
from ._driver_model import DEFAULT_PERTURBATION_PENALTY as DEFAULT_PERTURBATION_PENALTY
from ._driver_model import DriverModel, make_driver_model
from ._friction_search import ANGLE_LEADS as ANGLE_LEADS
from ._friction_search import FILTER_CANDIDATES as FILTER_CANDIDATES
from ._friction_search import SLOW_FILTER_CANDIDATES as SLOW_FILTER_CANDIDATES
from ._friction_search import WIDTH_GRID as WIDTH_GRID
from ._pipeline import TorquePipeline, make_torque_pipeline
from ._steering_features import SteeringFeatures

__all__ = [
    "DriverModel",
    "SteeringFeatures",
    "TorquePipeline",
    "make_driver_model",
    "make_torque_pipeline",
]
