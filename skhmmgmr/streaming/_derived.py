"""Derived inputs one sensed row at a time: the transformers of a fitted Pipeline, streamed.

:class:`~skhmmgmr.FilterStream` streams a fitted Pipeline whose transformers describe
themselves with a ``stream_settings()`` method (:meth:`SteeringFeatures.stream_settings
<skhmmgmr.SteeringFeatures.stream_settings>`) and whose last step is a fitted
:class:`~skhmmgmr.HMMGMRRegressor`. The pipeline's module sits above this one, so nothing here
imports it: a step is read through the plain description it returns, a dict of

``n_features_in`` (int), ``feature_names_in`` (list of str or None), ``feature_names_out``
(list of str), ``friction_position`` (int or None: no friction input), ``friction_velocity``
(float: one band; a list of floats: the widths of a basis, one friction input each),
``filter_decay`` (float or None: no velocity filter), ``sampling_period`` (float or
None), ``angle_position`` (int or None: no hysteresis input), ``friction_angle`` (list of
floats: the plays' half-widths), ``load_positions`` (list of int) and ``powers`` (list of
int); optionally ``angle_lead`` (float or None) and ``lead_position`` (int or None): the plays
read ``angle + angle_lead * velocity``, the velocity at ``lead_position`` (a description
without them has no lead); optionally ``slow_filter_decay`` (float or None): the factor per row
of a second, slow filter on the (unfiltered) velocity, whose friction inputs, of the same
widths, follow the others (a description without it has none).

Every step appends its derived inputs to its input row, so the row the regressor reads is the
sensed row followed by every step's derived inputs. An update reads the sensed row as a Python
list once and computes the derived inputs with scalar operations (a handful per input); the
only state is the velocity filters' and the plays' positions, restarted at every recording.
"""

import math

import numpy as np

from .._core._sequences import as_recordings
from .._core._validation import check_filter_period

SETTINGS = (
    "n_features_in",
    "feature_names_in",
    "feature_names_out",
    "friction_position",
    "friction_velocity",
    "filter_decay",
    "sampling_period",
    "angle_position",
    "friction_angle",
    "load_positions",
    "powers",
)


class DerivedInputs:
    """The derived inputs of one step, sample by sample, with its velocity filter's state.

    The velocity filter is that of :func:`skhmmgmr.torque_pipeline.low_pass` one sample at a
    time: it starts at the first observed velocity of the recording (its output equals it
    there), ``y = decay y_last + (1 - decay) x`` for the next ones, and a missing velocity
    gives a missing friction input and leaves the state alone, the next observed one then
    taken in over the whole time since the last, ``decay^(g+1)`` after ``g`` missing ones. An
    infinite velocity is read as missing (the batch filter would carry it on for the rest of
    the recording). The plays of the hysteresis inputs are those of
    :func:`skhmmgmr.torque_pipeline._derived_inputs.hysteresis_input` one sample at a time:
    started at the recording's first observed angle, a missing (or infinite) angle gives
    missing hysteresis inputs and leaves them alone.

    The slow velocity filter (``slow_filter_decay``) is a second such filter on the unfiltered
    velocity, with its own state.

    Parameters
    ----------
    settings : dict
        The step's ``stream_settings()`` (see the module's docstring).
    """

    def __init__(self, settings):
        missing = [key for key in SETTINGS if key not in settings]
        if missing:
            raise ValueError(f"stream settings lack {missing}")
        self.n_features_in = int(settings["n_features_in"])
        names = settings["feature_names_in"]
        self.feature_names_in = None if names is None else list(names)
        self.feature_names_out = list(settings["feature_names_out"])
        self.friction = settings["friction_position"]
        self.friction_velocity = settings["friction_velocity"]
        widths = self.friction_velocity
        self.widths = tuple(widths) if isinstance(widths, list | tuple) else (widths,)
        decay = settings["filter_decay"]
        slow = settings.get("slow_filter_decay")
        self.slow = None if slow is None else LowPass(slow)
        self.sampling_period = settings["sampling_period"]
        self.angle = settings["angle_position"]
        self.radii = tuple(float(r) for r in settings["friction_angle"] or ())
        self.lead = settings.get("angle_lead")
        self.lead_position = settings.get("lead_position")
        self.loads = tuple(int(p) for p in settings["load_positions"])
        self.powers = tuple(int(p) for p in settings["powers"])
        self.filter = None if decay is None else LowPass(decay)
        self.reset()

    def __setstate__(self, state):
        # a stream pickled before the filters were LowPass objects held one filter's state;
        # one pickled before this release also kept the decay beside its LowPass
        state = dict(state)
        decay = state.pop("decay", None)
        if "filter" not in state:
            state["filter"] = None if decay is None else LowPass(decay)
            if decay is not None:
                state["filter"].filtered = state.pop("filtered", None)
                state["filter"].since = state.pop("since", 0)
            state["slow"] = None
            state.pop("gain", None)
        self.__dict__.update(state)

    @property
    def n_features_out(self):
        return len(self.feature_names_out)

    def reset(self):
        """Restart the velocity filters and the plays (a new recording)."""
        for low_pass in (self.filter, self.slow):
            if low_pass is not None:
                low_pass.reset()
        self.plays = None  # the plays' positions, from the first observed angle

    def append(self, values):
        """Append the derived inputs of one row (a list of floats, extended in place)."""
        if self.friction is not None:
            measured = values[self.friction]
            velocity = measured if self.filter is None else self.filter.step(measured)
            for width in self.widths:
                values.append(math.tanh(velocity / width))
            if self.slow is not None:
                slow = self.slow.step(measured)
                for width in self.widths:
                    values.append(math.tanh(slow / width))
        if self.angle is not None:
            angle = values[self.angle]
            if self.lead is not None:
                angle = angle + self.lead * values[self.lead_position]
            values.extend(self.hysteresis(angle))
        powers = self.powers
        for position in self.loads:
            x = values[position]
            size = abs(x)
            for power in powers:
                try:
                    value = size**power
                except OverflowError:  # the batch transform's inf, held as non-finite
                    value = math.inf
                values.append(value if x >= 0.0 else -value)

    def hysteresis(self, angle):
        """The hysteresis inputs of the next row's angle (NaN for a missing one)."""
        if not math.isfinite(angle):
            return [math.nan] * len(self.radii)
        if self.plays is None:
            self.plays = [angle] * len(self.radii)
        out = []
        for j, radius in enumerate(self.radii):
            position = self.plays[j]
            if position < angle - radius:
                position = angle - radius
            elif position > angle + radius:
                position = angle + radius
            self.plays[j] = position
            out.append((angle - position) / radius)
        return out

    def check_time(self, time, groups):
        """Refuse time stamps whose median step in a recording is not ``sampling_period``
        (within 1 %), as the step's own transform does (for the velocity filters)."""
        if (self.filter is None and self.slow is None) or time is None:
            return
        recordings = as_recordings(groups, len(time))
        check_time_steps(np.asarray(time, dtype=float), recordings, self.sampling_period)

    def __repr__(self):
        return f"DerivedInputs({self.n_features_in} -> {self.n_features_out} inputs)"


class LowPass:
    """A causal first-order filter of decay ``decay`` per row, one sample at a time: that of
    :func:`skhmmgmr.torque_pipeline._derived_inputs.low_pass` (see :class:`DerivedInputs`)."""

    def __init__(self, decay):
        self.decay = float(decay)
        self.gain = 1.0 - self.decay
        self.reset()

    def reset(self):
        self.filtered = None  # the output at the last observed value
        self.since = 0  # rows since that value

    def step(self, value):
        """The filtered value of the next row (NaN for a missing one)."""
        self.since += 1
        if not math.isfinite(value):
            return math.nan
        decay, gain, last = self.decay, self.gain, self.filtered
        # The operations of the batch filter (scipy's lfilter started at ``zi``), in its order.
        if last is None:
            last = gain * value + decay * value
        elif self.since == 1:
            last = gain * value + decay * last
        else:
            lapse = decay**self.since
            last = gain * value + (lapse * last + (decay - lapse) * value)
        self.filtered, self.since = last, 0
        return last


def check_time_steps(time, recordings, period):
    """Refuse a time level whose median step in a recording is not the sampling period
    ``period`` (within 1 %): the velocity filter's time constant would be off by their ratio."""
    for rec, start, stop in zip(recordings.ids, recordings.starts, recordings.stops, strict=True):
        if stop - start < 2:
            continue
        median = float(np.median(np.diff(time[start:stop])))
        check_filter_period(
            median,
            period,
            what=f"The time level of X steps {median:.6g} s (median) in recording {rec!r}",
            remedy="Pass the recordings' own period, or resample them (resample_recordings).",
        )


def stream_capable(step):
    """Whether a Pipeline step is streamed: it describes itself (or passes rows through)."""
    return step is None or step == "passthrough" or callable(getattr(step, "stream_settings", None))


def read_pipeline(pipeline):
    """The derived-input stages and the final estimator of a fitted Pipeline.

    Refuses, naming the step, a transformer that does not stream and a final step that is not
    an estimator with a fitted model; the stages must chain (every step reads the columns the
    step before it gives).
    """
    steps = list(pipeline.steps)
    if not steps:
        raise TypeError("FilterStream got a Pipeline without steps")
    kind = (
        "FilterStream streams a fitted HMMGMRRegressor, or a fitted Pipeline of SteeringFeatures "
        "steps ending in one"
    )
    for name, step in steps[:-1]:
        if not stream_capable(step):
            raise TypeError(
                f"{kind}; the Pipeline's step {name!r} ({type(step).__name__}) cannot be "
                "streamed. Stream the regressor alone (pipeline[-1].filter_stream()) on rows "
                "that went through the other steps, or derive those columns before the fit."
            )
    name, final = steps[-1]
    if final is None or final == "passthrough" or not hasattr(final, "filter_stream"):
        raise TypeError(
            f"{kind}; the Pipeline's last step {name!r} ({type(final).__name__}) is not an "
            "HMMGMRRegressor."
        )
    stages = [
        DerivedInputs(step.stream_settings())
        for _, step in steps[:-1]
        if step is not None and step != "passthrough"
    ]
    for before, after in zip(stages, stages[1:], strict=False):
        check_chain(before.n_features_out, before.feature_names_out, after)
    return stages, (name, final)


def check_chain(n_features, names, stage):
    """Refuse a stage that does not read the ``n_features`` columns (``names``) given to it."""
    if stage.n_features_in != n_features or (
        stage.feature_names_in is not None and list(stage.feature_names_in) != list(names)
    ):
        raise ValueError(
            f"A step of the Pipeline reads {stage.n_features_in} inputs "
            f"{stage.feature_names_in or []} but the step before it gives {n_features} "
            f"{list(names)}: was the Pipeline fitted as a whole?"
        )


def check_final(stages, n_inputs, names):
    """Refuse a final model that does not read the columns the last stage gives."""
    last = stages[-1]
    if last.n_features_out != n_inputs or (
        names is not None and list(names) != last.feature_names_out
    ):
        raise ValueError(
            f"The Pipeline's regressor reads {n_inputs} inputs {list(names or [])} but its "
            f"steps give {last.n_features_out} {last.feature_names_out}: was the Pipeline "
            "fitted as a whole?"
        )
