"""skhmmgmr: Hidden Markov Model + Gaussian Mixture Regression for scikit-learn."""

__version__ = "0.1.0.dev0"

from .estimator import HMMGMRRegressor

__all__ = ["HMMGMRRegressor", "__version__"]
