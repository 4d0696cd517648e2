"""The measured outputs an adapting :class:`~skhmmgmr.FilterStream` learns: one sample's
(``update(..., target=)``) or a batch's (``update_batch(..., y=)``), checked against the
model's outputs before any sample is consumed."""

import numbers

import numpy as np


def read_target(target, n_outputs, scalar_output):
    """The measured outputs of one sample as a float (``scalar_output``) or an array of shape
    (n_outputs,); ValueError naming ``target`` for anything else."""
    if (
        scalar_output
        and isinstance(target, numbers.Real)
        and not isinstance(target, (bool, np.bool_))
    ):
        return float(target)
    try:
        values = np.asarray(target, dtype=float)
    except (TypeError, ValueError):
        values = None
    if (
        values is None
        or values.ndim > 1
        or values.size != n_outputs
        or (isinstance(target, (bool, np.bool_)))
    ):
        raise ValueError(
            f"target must be the {n_outputs} measured output(s) of the sample "
            f"(NaN if unknown), got {target!r:.100}"
        )
    return float(values[0]) if scalar_output else values.reshape(n_outputs)


def read_targets(y, n_samples, n_outputs, scalar_output):
    """The measured outputs of a batch, shape (n_samples,) or (n_samples, n_outputs);
    ValueError naming ``y`` for anything else."""
    try:
        values = np.asarray(y, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"y must hold numbers (NaN if unknown): {exc}") from None
    expected = (n_samples,) if scalar_output else (n_samples, n_outputs)
    if scalar_output and values.shape == (n_samples, 1):
        values = values[:, 0]
    if values.shape != expected:
        raise ValueError(
            f"y has shape {values.shape}; the batch of {n_samples} rows of a model with "
            f"{n_outputs} output(s) needs shape {expected}"
        )
    return values
