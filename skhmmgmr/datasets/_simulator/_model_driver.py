"""A model at the simulator's wheel (:func:`drive`, :func:`torque_ahead`): its inputs found by
name among the sensed features, refused when its velocity filter was made for another sampling
period than the simulation's, and what it returns checked: one real, finite torque a sample.
"""

import reprlib

import numpy as np
import pandas as pd

from ..._core._schema import FEATURE_NAMES
from ..._core._validation import check_filter_period


def torque_function(driver, sampling_rate):
    """``(name, torque_of(row))`` of a model or a callable driver of :func:`drive`."""
    if hasattr(driver, "filter_stream"):
        stream, positions = model_stream(driver, sampling_rate)
        return type(driver).__name__, lambda row: stream.update(row[positions])
    if hasattr(driver, "predict"):
        positions = input_positions(driver)
        check_rate(driver, sampling_rate)
        columns = [FEATURE_NAMES[i] for i in positions]

        def predict_one(row):
            return driver.predict(pd.DataFrame([row[positions]], columns=columns))

        return type(driver).__name__, predict_one
    if callable(driver):
        return getattr(driver, "__name__", type(driver).__name__), driver
    raise TypeError(
        "driver must be a style name, a fitted model, an FMU (a .fmu path) or a callable; "
        f"got {type(driver).__name__}."
    )


def model_stream(model, sampling_rate):
    """A fresh filter stream of ``model`` and the positions of its inputs in a sensed row."""
    stream = model.filter_stream()
    positions = input_positions(model)
    check_rate(model, sampling_rate)
    return stream, positions


def input_positions(model):
    """The positions in a sensed row (:data:`FEATURE_NAMES`) of the inputs ``model`` reads by
    name (``feature_names_in_``)."""
    names = getattr(model, "feature_names_in_", None)
    if names is None:
        raise ValueError(
            f"{type(model).__name__} has no feature_names_in_: fit it on a DataFrame whose "
            f"columns are sensed features ({', '.join(FEATURE_NAMES)}) so that drive can "
            "give it its inputs by name."
        )
    unknown = [str(n) for n in names if n not in FEATURE_NAMES]
    if unknown:
        raise ValueError(
            f"{type(model).__name__} reads {unknown}, which the simulator does not sense; "
            f"it senses {list(FEATURE_NAMES)}."
        )
    return np.array([FEATURE_NAMES.index(n) for n in names])


def check_rate(model, sampling_rate):
    """Refuse a fitted pipeline whose velocity filter (a step's ``stream_settings()``) was made
    for another sampling period than ``1 / sampling_rate``, with ``predict``'s rule and words."""
    step = 1.0 / sampling_rate
    for name, transformer in getattr(model, "steps", ())[:-1]:
        settings = getattr(transformer, "stream_settings", None)
        if not callable(settings):
            continue
        settings = settings()
        if settings["filter_decay"] is None:
            continue
        period = settings["sampling_period"]
        check_filter_period(
            step,
            period,
            what=f"The simulation steps {step:.6g} s (sampling_rate={sampling_rate:g})",
            remedy=f"Simulate at the rate the step {name!r} of {type(model).__name__} was fitted "
            f"for (sampling_rate={1.0 / period:g}), or fit it at this one.",
        )


def as_torque(value, who, time):
    """``value`` as one real, finite torque, or a ValueError naming ``who`` returned it
    (``"The driver f"``) and the ``time`` [s]."""
    try:
        values = np.asarray(value)
    except ValueError:  # a ragged sequence
        values = np.asarray(None)
    if values.dtype.kind not in "iuf":
        raise ValueError(
            f"{who} returned {reprlib.repr(value)} at {time:.3f} s; a torque is a real number [Nm]."
        )
    if values.size != 1:
        raise ValueError(
            f"{who} returned {values.size} values at {time:.3f} s; one torque is expected."
        )
    torque = float(values.ravel()[0])
    if not np.isfinite(torque):
        raise ValueError(f"{who} returned a non-finite torque ({torque}) at {time:.3f} s.")
    return torque
