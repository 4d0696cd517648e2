"""
A portable model file and a filter that needs only NumPy
========================================================

A steering controller does not run scikit-learn. :func:`skhmmgmr.portable.save` writes
everything the causal HMM-GMR filter needs into one JSON file (the format is described in
:mod:`skhmmgmr.portable`). This example fits a small model, saves it, and runs a reference
implementation of the filter that reads only that file: plain NumPy, no skhmmgmr import. Its
estimates match :meth:`~skhmmgmr.HMMGMRRegressor.predict` to round-off.
"""

# %%
# The reference filter
# --------------------
# The filter runs on standardised inputs. For every sample it computes the input log-density of
# every state from the precision Cholesky factors, takes the densities relative to the largest
# one, runs one step of the normalised forward recursion (restarting from the densities alone
# if every state is ruled out), and mixes the per-state linear regressions.
import json

import numpy as np


def portable_filter(path, X):
    """Causal HMM-GMR estimates and stds of one recording ``X`` from a portable model file."""
    with open(path, encoding="utf-8") as file:
        model = json.load(file)
    if model["format"] != "skhmmgmr-hmm-gmr" or model["format_version"] not in (1, 2):
        raise ValueError("not a skhmmgmr-hmm-gmr model file of format version 1 or 2")
    if model.get("model_type", "HMMGMRRegressor") != "HMMGMRRegressor":
        # a pipeline: its last step holds the regressor, whose inputs the steps before derive
        raise ValueError(f"{model['model_type']}: this filter reads a regressor's file")
    scaling, params = model["standardization"], model["filter"]
    start = np.array(params["start_probabilities"])
    transition = np.array(params["transition_matrix"])
    means = np.array(params["input_means"])
    precision_chol = np.array(params["input_precision_cholesky"])
    coef = np.array(params["regression_coefficients"])
    intercept = np.array(params["regression_intercepts"])
    conditional_var = np.diagonal(np.array(params["conditional_covariances"]), axis1=1, axis2=2)
    n_states, n_inputs = means.shape
    log_norm = np.log(np.diagonal(precision_chol, axis1=1, axis2=2)).sum(axis=1)
    log_norm -= 0.5 * n_inputs * np.log(2.0 * np.pi)

    Z = (np.asarray(X, dtype=float) - scaling["input_center"]) / scaling["input_scale"]
    estimates, stds = [], []
    prior = start
    for z in Z:
        log_density = np.array(
            [
                log_norm[k] - 0.5 * np.sum(((z - means[k]) @ precision_chol[k]) ** 2)
                for k in range(n_states)
            ]
        )
        density = np.exp(log_density - log_density.max())
        alpha = prior * density
        if alpha.sum() == 0.0:
            alpha = density
        alpha = alpha / alpha.sum()
        state_means = np.array([coef[k] @ z + intercept[k] for k in range(n_states)])
        estimate = alpha @ state_means
        variance = alpha @ conditional_var + alpha @ (state_means - estimate) ** 2
        estimates.append(estimate)
        stds.append(np.sqrt(variance))
        prior = alpha @ transition
    estimates = np.array(estimates) * scaling["output_scale"] + scaling["output_center"]
    stds = np.array(stds) * scaling["output_scale"]
    return estimates, stds


# %%
# Fit, export, compare
# --------------------
# The demonstration is guarded so that the tests can import ``portable_filter`` alone.
if __name__ == "__main__":
    import os
    import tempfile

    from skhmmgmr import HMMGMRRegressor, portable

    rng = np.random.default_rng(0)
    X = np.cumsum(rng.normal(scale=0.2, size=(600, 3)), axis=0)
    y = 2.0 * np.tanh(X[:, 0]) - 0.5 * X[:, 1] + rng.normal(scale=0.05, size=600)
    groups = np.repeat(["a", "b"], 300)
    model = HMMGMRRegressor(n_states=3, random_state=0).fit(X, y, groups=groups)

    path = os.path.join(tempfile.mkdtemp(), "steering_model.json")
    portable.save(model, path, output_names=["steering_torque"])
    print(f"saved {os.path.getsize(path)} bytes to {path}")

    rows = groups == "b"
    reference, reference_std = portable_filter(path, X[rows])
    predicted, predicted_std = model.predict(X[rows], return_std=True)
    print("max |reference - predict|:", np.abs(reference[:, 0] - predicted).max())
    print("max |reference std - predict std|:", np.abs(reference_std[:, 0] - predicted_std).max())
