"""Derived inputs that the physics of a power-assisted steering system motivates, and the
torque pipeline that puts them in front of :class:`~skhmmgmr.HMMGMRRegressor`.

The driver torque balances, through the power assist, the steering system's load: the
self-aligning torque of the front tyres, the wheel's inertia and damping, and Coulomb friction.
Two parts of that balance are not linear in any sensed input, and a mixture of local linear
regressions gated by Gaussians can follow them only with many states:

- **friction** switches sign with the steering-wheel velocity over a few hundredths of a radian
  per second: ``tanh(steering_wheel_velocity / friction_velocity)``;
- **the steering load is compressed**: the boost curve of an electric power assist grows with
  the torque (the driver's share of a large load is smaller), and the tyres' aligning torque
  saturates with slip. Odd powers of the load's proxies (the steering-wheel angle and the lateral
  acceleration: ``x |x|`` and ``x^3``) are the first terms of any smooth odd curve.

Each derived input is an ordinary named column: :class:`SteeringFeatures` appends them to a
data frame, so the selection framework keeps or drops them like any other feature. At high
sampling rates the measured velocity is noisy at the scale of the friction band; a causal
first-order filter (``velocity_filter``, within each recording) keeps that noise out of the
friction input.

The friction band is the steering system's, and whether the velocity needs the filter depends
on its sensor: both differ from car to car. With ``"auto"`` (the default of
:func:`make_torque_pipeline`) ``fit`` chooses them on the training recordings: every
candidate of ``FRICTION_CANDIDATES`` and ``FILTER_CANDIDATES`` is scored by the
held-out error of a least-squares fit of the target on the inputs and the derived inputs, the
recordings split in ``SEARCH_FOLDS`` folds, and the candidate of least error is kept. A
linear fit ranks the candidates nearly as the regressor does (the friction input enters every
state's regression alike) at a small part of its cost.
"""

import inspect
import math
import numbers

import numpy as np
import pandas as pd
from scipy.signal import lfilter
from sklearn.base import BaseEstimator, TransformerMixin
from sklearn.pipeline import Pipeline
from sklearn.utils.metaestimators import available_if
from sklearn.utils.validation import check_is_fitted, validate_data

from ._core._compat import (
    Interval,
    StrOptions,
    _fit_context,
    _routing_enabled,
    validate_parameter_constraints,
)
from ._core._docstrings import fill_shared_parameters
from ._core._panel import align_target, has_recording_index, read_layout
from ._core._pickled import PickleVersionMixin
from .estimator import HMMGMRRegressor
from .streaming import FilterStream
from .streaming._derived import check_time_steps

__all__ = [
    "DriverModel",
    "SteeringFeatures",
    "TorquePipeline",
    "make_driver_model",
    "make_torque_pipeline",
]

FRICTION_NAME = "steering_friction"
#: The friction bands [rad/s] ``friction_velocity="auto"`` compares (a factor 2 apart, over the
#: bands of passenger cars' steering systems).
FRICTION_CANDIDATES = (0.025, 0.05, 0.1, 0.2, 0.4, 0.8)
#: The velocity filters [s] ``velocity_filter="auto"`` compares (``None``: no filter).
FILTER_CANDIDATES = (None, 0.02, 0.05)
#: Folds of the inner validation of the "auto" choices.
SEARCH_FOLDS = 3
AUTO = "auto"


def _power_name(column, power):
    if power == 2:
        return f"{column}_signed_square"
    if power == 3:
        return f"{column}_cube"
    return f"{column}_signed_power{power}"


def _column_label(column):
    return f"x{column}" if isinstance(column, numbers.Integral) else str(column)


def low_pass(values, decay):
    """One recording through the causal first-order filter ``y_t = decay y_(t-1) + (1 - decay)
    x_t``, started at its first observed value (``y = x`` there).

    A missing value (NaN) gives NaN and leaves the filter's state alone; the next observed
    value ``x`` after ``g`` missing ones is taken in over the ``g + 1`` periods since the last
    observed one, ``y = decay^(g+1) y_last + (1 - decay^(g+1)) x`` (the filter's exact answer to
    ``x`` held over that time), so that a missing sample never spreads.
    """
    filtered = np.full(len(values), np.nan)
    observed = np.flatnonzero(~np.isnan(values))
    if not observed.size:
        return filtered
    # runs of consecutive observed rows
    breaks = np.flatnonzero(np.diff(observed) > 1) + 1
    last = last_row = None
    for run in np.split(observed, breaks):
        x = values[run[0] : run[-1] + 1]
        if last is None:  # the recording's first observed value: y = x
            start = decay * x[0]
        else:  # after a gap of g missing rows, as above; the lfilter adds (1 - decay) x[0]
            lapse = decay ** (run[0] - last_row)
            start = lapse * last + (decay - lapse) * x[0]
        filtered[run[0] : run[-1] + 1] = lfilter([1.0 - decay], [1.0, -decay], x, zi=[start])[0]
        last, last_row = filtered[run[-1]], run[-1]
    return filtered


@fill_shared_parameters
class SteeringFeatures(PickleVersionMixin, TransformerMixin, BaseEstimator):
    """Append the friction and load-compression inputs of a power-assisted steering system.

    Only the ``"auto"`` settings are learned: ``fit`` chooses the friction band and the
    velocity filter on the target by a grouped inner validation (see the module's docstring
    and ``friction_search_``). Without a velocity filter the transform is row by row, so it is
    causal and streams: the same row always gives the same derived inputs. With it, the
    friction input reads the velocity through a causal first-order filter that restarts at
    every recording (the recordings come from ``groups`` or from the index of a panel,
    :func:`skhmmgmr.datasets.to_panel`; without either, the rows form one recording in time
    order). Missing values (NaN) stay missing.

    Parameters
    ----------
    friction_velocity : float, "auto" or None, default=0.1
        Steering-wheel velocity [rad/s] over which Coulomb friction changes sign; the derived
        input ``steering_friction`` is ``tanh(velocity / friction_velocity)``. ``"auto"``: the
        band of 0.025, 0.05, 0.1, 0.2, 0.4 and 0.8 rad/s (``FRICTION_CANDIDATES``) of least
        held-out error, chosen in ``fit`` (which then needs ``y``). ``None`` adds no friction input.
    friction_column : str or int, default="steering_wheel_velocity"
        The column holding the steering-wheel velocity (a name, or a position for arrays).
    load_columns : tuple of str or int, default=("steering_wheel_angle", "lateral_acceleration")
        Proxies of the steering load whose odd powers are appended.
    powers : tuple of int, default=(2, 3)
        Powers ``p >= 2`` appended for each load column as ``sign(x) |x|^p``, named
        ``<column>_signed_square`` (2), ``<column>_cube`` (3) or ``<column>_signed_power<p>``.
    velocity_filter : float, "auto" or None, default=None
        Time constant [s] of a causal first-order low-pass filter on the velocity before the
        friction input (0.02 s suits 100 Hz sensors; at 20 Hz it changes little). ``None``
        filters nothing. A time constant needs ``sampling_period``. ``"auto"``: none, 0.02 or
        0.05 s (``FILTER_CANDIDATES``), chosen in ``fit`` with the friction band (no filter
        without ``sampling_period``). The filter starts at the first observed
        velocity of each recording (its output equals it there); a missing velocity gives a
        missing friction input and leaves the filter's state alone, and the next observed
        velocity is taken in over the whole time since the last one.
    {sampling_period}

    Attributes
    ----------
    friction_velocity_ : float or None
        The friction band the transform uses: ``friction_velocity``, or the one chosen.
    velocity_filter_ : float or None
        The velocity filter's time constant the transform uses (``None``: no filter).
    friction_search_ : DataFrame or None
        The ``"auto"`` choice: one row per candidate, with ``friction_velocity``,
        ``velocity_filter``, ``validation_rmse`` (held-out root mean squared error of the
        linear fit, in the target's unit) and ``chosen``; ``None`` without an ``"auto"``
        setting.
    n_features_in_ : int
        Number of input columns.
    feature_names_in_ : ndarray of shape (n_features,)
        Input column names, when fitted on a data frame whose column names are all strings.

    See Also
    --------
    make_torque_pipeline : These inputs in front of :class:`~skhmmgmr.HMMGMRRegressor`.

    Examples
    --------
    >>> import pandas as pd
    >>> from skhmmgmr import SteeringFeatures
    >>> X = pd.DataFrame({"steering_wheel_angle": [0.1, -0.2],
    ...                   "steering_wheel_velocity": [0.0, 0.5],
    ...                   "lateral_acceleration": [1.0, -2.0]})
    >>> derived = SteeringFeatures().fit_transform(X)
    >>> list(derived.columns[3:])  # doctest: +NORMALIZE_WHITESPACE
    ['steering_friction', 'steering_wheel_angle_signed_square', 'steering_wheel_angle_cube',
     'lateral_acceleration_signed_square', 'lateral_acceleration_cube']
    >>> derived["lateral_acceleration_signed_square"].tolist()
    [1.0, -4.0]

    With ``"auto"`` (the default of :func:`make_torque_pipeline`) ``fit`` chooses them on the
    torque:

    >>> from skhmmgmr.datasets import FEATURE_NAMES, make_lane_keeping
    >>> data = make_lane_keeping(60.0, sampling_rate=20.0, random_state=0)
    >>> step = SteeringFeatures(friction_velocity="auto", velocity_filter="auto")
    >>> step = step.fit(data[list(FEATURE_NAMES)], data["driver_torque"])
    >>> step.friction_velocity_, step.velocity_filter_
    (0.1, None)
    """

    _parameter_constraints = {
        "friction_velocity": [
            Interval(numbers.Real, 0, None, closed="neither"),
            StrOptions({AUTO}),
            None,
        ],
        "friction_column": [str, Interval(numbers.Integral, 0, None, closed="left")],
        "load_columns": [tuple, list],
        "powers": [tuple, list],
        "velocity_filter": [
            Interval(numbers.Real, 0, None, closed="neither"),
            StrOptions({AUTO}),
            None,
        ],
        "sampling_period": [Interval(numbers.Real, 0, None, closed="neither"), None],
    }

    def __init__(
        self,
        friction_velocity=0.1,
        friction_column="steering_wheel_velocity",
        load_columns=("steering_wheel_angle", "lateral_acceleration"),
        powers=(2, 3),
        velocity_filter=None,
        sampling_period=None,
    ):
        self.friction_velocity = friction_velocity
        self.friction_column = friction_column
        self.load_columns = load_columns
        self.powers = powers
        self.velocity_filter = velocity_filter
        self.sampling_period = sampling_period

    __metadata_request__fit = {"groups": True}
    __metadata_request__transform = {"groups": True}

    @_fit_context(prefer_skip_nested_validation=True)
    def fit(self, X, y=None, groups=None):
        """Check that ``X`` holds the named columns; choose the ``"auto"`` settings.

        Parameters
        ----------
        X : DataFrame or array-like of shape (n_samples, n_features)
            Sensed inputs. Columns are found by name in a data frame, by position in an array.
        y : array-like of shape (n_samples,) or (n_samples, n_outputs), default=None
            The target (the driver torque); needed by an ``"auto"`` setting, ignored
            otherwise.
        groups : array-like of shape (n_samples,), default=None
            Recording id of every row: the folds of the ``"auto"`` choice are whole
            recordings, and the velocity filter restarts at each. ``None``: the index's
            recording level if any, else one recording.

        Returns
        -------
        self : SteeringFeatures
            The fitted transformer.
        """
        self._check_parameters()
        values = validate_data(self, X, ensure_all_finite="allow-nan", reset=True)
        self._check_inputs()
        self.friction_velocity_ = self.friction_velocity
        self.velocity_filter_ = self.velocity_filter
        self.friction_search_ = None
        if self.friction_velocity is None:
            self.velocity_filter_ = None
        elif AUTO in (self.friction_velocity, self.velocity_filter):
            self.friction_search_ = self._search(values, X, y, groups)
            chosen = self.friction_search_[self.friction_search_["chosen"]].iloc[0]
            self.friction_velocity_ = float(chosen["friction_velocity"])
            self.velocity_filter_ = chosen["velocity_filter"]
            if self.velocity_filter_ is not None:
                self.velocity_filter_ = float(self.velocity_filter_)
        return self

    def _candidates(self):
        """The (friction band, velocity filter) pairs the inner validation compares."""
        bands = FRICTION_CANDIDATES if self.friction_velocity == AUTO else (self.friction_velocity,)
        if self.velocity_filter != AUTO:
            filters = (self.velocity_filter,)
        elif self.sampling_period is None:  # a filter needs the time between two rows
            filters = (None,)
        else:
            filters = FILTER_CANDIDATES
        return [(band, time_constant) for time_constant in filters for band in bands]

    def _search(self, values, X, y, groups):
        """The table of the ``"auto"`` choice: every candidate's validation RMSE."""
        if y is None:
            raise ValueError(
                f"friction_velocity={self.friction_velocity!r}, "
                f"velocity_filter={self.velocity_filter!r}: an 'auto' setting is chosen on the "
                "target, so fit needs y (the torque)."
            )
        layout = read_layout(X, groups)
        target = np.asarray(align_target(X, y, layout), dtype=float)
        target = target.reshape(len(values), -1)
        positions = self._sources()
        base = [values, *self._load_inputs(values, positions).values()]
        velocity = values[:, positions[self.friction_column]]
        folds = _search_folds(layout, len(values))
        velocities, rows = {}, []
        for band, time_constant in self._candidates():
            if time_constant not in velocities:
                velocities[time_constant] = (
                    velocity
                    if time_constant is None
                    else self._filtered(velocity, X, groups, self._decay(time_constant))
                )
            rows.append((band, time_constant, np.tanh(velocities[time_constant] / band)))
        rmse = _validation_rmse(np.column_stack(base), [f for *_, f in rows], target, folds, self)
        best = int(np.argmin(rmse))  # the first of equal ones: the order above
        return pd.DataFrame(
            {
                "friction_velocity": [float(band) for band, _, _ in rows],
                "velocity_filter": pd.Series([tc for _, tc, _ in rows], dtype=object),
                "validation_rmse": rmse,
                "chosen": np.arange(len(rows)) == best,
            }
        )

    def _check_parameters(self):
        """What the parameters' constraints cannot say: the powers, the load columns, and
        ``sampling_period`` with ``velocity_filter``."""
        self._check_powers()
        if self.velocity_filter not in (None, AUTO) and self.sampling_period is None:
            raise ValueError(
                f"velocity_filter={self.velocity_filter!r} needs sampling_period (the seconds "
                "between two rows); got sampling_period=None."
            )

    def _check_inputs(self):
        """The fitted inputs hold the source columns and none of the derived ones."""
        self._sources()
        inputs = [str(name) for name in getattr(self, "feature_names_in_", ())]
        taken = [name for name in self._derived_names() if name in inputs]
        if taken:
            raise ValueError(
                f"X already has the column(s) {taken}, which SteeringFeatures derives: rename "
                "them, or leave their source out (friction_velocity=None for the friction "
                "input, load_columns or powers for the others)."
            )

    def fit_transform(self, X, y=None, groups=None):
        """Fit, then append the derived inputs (see :meth:`transform`).

        Parameters
        ----------
        X : DataFrame or array-like of shape (n_samples, n_features)
            Sensed inputs.
        y : array-like of shape (n_samples,) or (n_samples, n_outputs), default=None
            The target, for an ``"auto"`` setting (see :meth:`fit`).
        groups : array-like of shape (n_samples,), default=None
            Recording id of every row, for ``velocity_filter`` and the ``"auto"`` choice.

        Returns
        -------
        X_out : DataFrame or ndarray of shape (n_samples, n_features)
            See :meth:`transform`.
        """
        return self.fit(X, y, groups=groups).transform(X, groups=groups)

    def transform(self, X, groups=None):
        """Append the derived inputs.

        Parameters
        ----------
        X : DataFrame or array-like of shape (n_samples, n_features)
            The columns seen in :meth:`fit`.
        groups : array-like of shape (n_samples,), default=None
            Recording id of every row, for ``velocity_filter`` (the filter restarts at every
            recording; the rows of a recording contiguous and in time order, unless the
            index of a panel orders them). ``None``: the index's recording level if any,
            else one recording.

        Returns
        -------
        X_out : DataFrame or ndarray of shape (n_samples, n_features)
            ``X`` followed by the derived inputs (``n_features`` is the number of input
            columns plus the number of derived inputs); a data frame keeps its index (the
            recordings of a panel) and its ``attrs``, with the units of the derived inputs
            added to ``attrs["units"]`` when the source columns have units there.
        """
        check_is_fitted(self, "n_features_in_")
        # a frame keeps its columns when they are names (strings), as scikit-learn reads them
        named = isinstance(X, pd.DataFrame) and hasattr(self, "feature_names_in_")
        frame = X if named else None
        values = validate_data(self, X, ensure_all_finite="allow-nan", reset=False)
        positions = self._sources()
        derived = {}
        if self.friction_velocity is not None:
            velocity = values[:, positions[self.friction_column]]
            if self.velocity_filter_ is not None:
                velocity = self._filtered(velocity, X, groups, self._decay())
            derived[FRICTION_NAME] = np.tanh(velocity / self.friction_velocity_)
        derived.update(self._load_inputs(values, positions))
        if frame is None:
            return np.column_stack([values, *derived.values()])
        out = pd.DataFrame(derived, index=frame.index)
        out = pd.concat([frame, out], axis=1)
        out.attrs = {**frame.attrs, "units": self._units(frame.attrs.get("units"))}
        if out.attrs["units"] is None:
            del out.attrs["units"]
        return out

    def get_feature_names_out(self, input_features=None):
        """Input names followed by the derived inputs' names.

        Parameters
        ----------
        input_features : array-like of str or None, default=None
            Input names; ``None`` means ``feature_names_in_`` (or ``x0``, ``x1``, ...).

        Returns
        -------
        feature_names_out : ndarray of str objects
            Output column names.
        """
        check_is_fitted(self, "n_features_in_")
        if input_features is None:
            input_features = getattr(
                self, "feature_names_in_", [f"x{i}" for i in range(self.n_features_in_)]
            )
        elif len(input_features) != self.n_features_in_:
            raise ValueError(
                f"input_features has {len(input_features)} names; "
                f"{self.n_features_in_} were seen in fit."
            )
        return np.asarray([*input_features, *self._derived_names()], dtype=object)

    def stream_settings(self):
        """What a sample-by-sample stream of :meth:`transform` needs, as plain values.

        :class:`~skhmmgmr.FilterStream` reads it to stream a fitted pipeline of these steps
        and the regressor on the sensed rows (``pipeline.filter_stream()``).

        Returns
        -------
        settings : dict
            ``n_features_in`` and ``feature_names_in`` (``None`` without names) of the input
            rows, ``feature_names_out``; ``friction_position`` (the velocity's position in the
            row, ``None`` without a friction input), ``friction_velocity``; ``filter_decay``,
            the velocity filter's factor per row ``exp(-sampling_period / velocity_filter)``
            (``None`` without the filter), and ``sampling_period``; ``load_positions`` (the
            load columns' positions) and ``powers``.

        Examples
        --------
        >>> import numpy as np
        >>> from skhmmgmr import SteeringFeatures
        >>> step = SteeringFeatures(friction_column=2, load_columns=(0,), powers=(3,),
        ...                         velocity_filter=0.02, sampling_period=0.01)
        >>> settings = step.fit(np.zeros((5, 3))).stream_settings()
        >>> settings["friction_position"], settings["load_positions"], settings["feature_names_out"]
        (2, [0], ['x0', 'x1', 'x2', 'steering_friction', 'x0_cube'])
        >>> round(settings["filter_decay"], 4)  # exp(-0.01 / 0.02)
        0.6065
        """
        check_is_fitted(self, "n_features_in_")
        positions = self._sources()
        names = getattr(self, "feature_names_in_", None)
        friction = self.friction_velocity is not None
        filtered = friction and self.velocity_filter_ is not None
        return {
            "n_features_in": int(self.n_features_in_),
            "feature_names_in": None if names is None else [str(name) for name in names],
            "feature_names_out": [str(name) for name in self.get_feature_names_out()],
            "friction_position": positions[self.friction_column] if friction else None,
            "friction_velocity": float(self.friction_velocity_) if friction else None,
            "filter_decay": self._decay() if filtered else None,
            "sampling_period": None
            if self.sampling_period is None
            else float(self.sampling_period),
            "load_positions": [positions[column] for column in self.load_columns],
            "powers": [int(power) for power in self.powers],
        }

    def _decay(self, time_constant=None):
        """The velocity filter's factor per row (the fitted filter's by default)."""
        if time_constant is None:
            time_constant = self.velocity_filter_
        return math.exp(-self.sampling_period / time_constant)

    def _load_inputs(self, values, positions):
        """The signed powers of the load columns, by name."""
        derived = {}
        for column in self.load_columns:
            x = values[:, positions[column]]
            for power in self.powers:
                derived[_power_name(_column_label(column), power)] = np.sign(x) * np.abs(x) ** power
        return derived

    def _derived_names(self):
        names = [FRICTION_NAME] if self.friction_velocity is not None else []
        names += [_power_name(_column_label(c), p) for c in self.load_columns for p in self.powers]
        return names

    def _filtered(self, velocity, X, groups, decay):
        """The velocity through the first-order filter of factor ``decay`` per row, restarted
        at every recording."""
        rows = read_layout(X, groups)
        ordered = rows.to_filter_order(velocity)
        recordings = rows.recordings(len(ordered))
        if rows.time is not None:
            check_time_steps(np.asarray(rows.time, dtype=float), recordings, self)
        filtered = np.empty_like(ordered)
        for start, stop in zip(recordings.starts, recordings.stops, strict=True):
            filtered[start:stop] = low_pass(ordered[start:stop], decay)
        return rows.to_caller_order(filtered)

    def _check_powers(self):
        for power in self.powers:
            if not isinstance(power, numbers.Integral) or isinstance(power, bool) or power < 2:
                raise ValueError(
                    f"powers must hold integers >= 2 (1 is the input itself); got {power!r} "
                    f"in powers={self.powers!r}."
                )
        if len(set(self.powers)) != len(self.powers):
            raise ValueError(f"powers={self.powers!r} repeats a power.")
        if len(set(self.load_columns)) != len(self.load_columns):
            raise ValueError(f"load_columns={self.load_columns!r} repeats a column.")

    def _sources(self):
        """Position of every source column, with an error naming the missing ones."""
        needed = list(self.load_columns)
        if self.friction_velocity is not None:
            needed.insert(0, self.friction_column)
        names = getattr(self, "feature_names_in_", None)
        positions, missing = {}, []
        for column in needed:
            if isinstance(column, str):
                if names is None or column not in names:
                    missing.append(column)
                else:
                    positions[column] = int(np.flatnonzero(names == column)[0])
            elif isinstance(column, numbers.Integral) and not isinstance(column, bool):
                if column >= self.n_features_in_:
                    missing.append(column)
                positions[column] = int(column)
            else:
                raise TypeError(f"columns are names or positions; got {column!r}.")
        if missing:
            where = (
                "X has no column names (pass a DataFrame, or positions for an array)"
                if names is None
                else f"X has columns {list(names)}"
            )
            raise ValueError(
                f"SteeringFeatures needs the column(s) {missing} (friction_column / "
                f"load_columns); {where}."
            )
        return positions

    def _units(self, units):
        if not isinstance(units, dict):
            return None
        units = dict(units)
        if self.friction_velocity is not None:
            units[FRICTION_NAME] = "1"
        for column in self.load_columns:
            unit = units.get(column)
            for power in self.powers:
                name = _power_name(_column_label(column), power)
                units[name] = None if unit is None else f"({unit})^{power}"
                if units[name] is None:
                    del units[name]
        return units

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        tags.input_tags.allow_nan = True
        tags.requires_fit = True
        return tags


def _search_folds(layout, n_samples):
    """The fold of every row (caller's order) for the inner validation: whole recordings, in
    turn, when there are at least ``SEARCH_FOLDS``; else every recording cut in that many
    consecutive blocks."""
    recordings = layout.recordings(n_samples)
    folds = np.empty(n_samples, dtype=np.intp)
    spans = list(zip(recordings.starts, recordings.stops, strict=True))
    for number, (start, stop) in enumerate(spans):
        if len(spans) >= SEARCH_FOLDS:
            folds[start:stop] = number % SEARCH_FOLDS
        else:
            folds[start:stop] = np.arange(stop - start) * SEARCH_FOLDS // (stop - start)
    return layout.to_caller_order(folds)


def _validation_rmse(base, candidates, target, folds, step):
    """Held-out RMSE of a least-squares fit of ``target`` on ``base`` and each candidate
    column, every fold left out in turn (the rows where any of them is missing left out).

    One pass over the rows per fold and candidate: the fits come from the folds' sums of
    products, the training sum being the total less the held-out fold's.
    """
    finite = np.isfinite(base).all(axis=1) & np.isfinite(target).all(axis=1)
    for column in candidates:
        finite &= np.isfinite(column)
    base, target, folds = base[finite], target[finite], folds[finite]
    used = [fold for fold in range(SEARCH_FOLDS) if np.any(folds == fold)]
    if len(used) < 2 or len(base) <= base.shape[1] + 2:
        raise ValueError(
            f"friction_velocity={step.friction_velocity!r}, "
            f"velocity_filter={step.velocity_filter!r}: the 'auto' choice needs rows with every "
            f"input and the target observed in at least 2 parts of the data; got "
            f"n_samples={len(base)} such rows. Give more recordings, or fixed values."
        )
    scale = base.std(axis=0)
    scale[scale == 0] = 1.0
    base = (base - base.mean(axis=0)) / scale
    base = np.column_stack([np.ones(len(base)), base])
    n_base, n_outputs = base.shape[1], target.shape[1]
    # every fold's rows, sums of products and base and target columns, once for all candidates
    parts = {}
    for fold in used:
        rows = folds == fold
        parts[fold] = (rows, base[rows], target[rows])
    sums = {
        fold: _products(fold_base, fold_target)
        for fold, (_, fold_base, fold_target) in parts.items()
    }
    rmse = []
    for column in candidates:
        column = column[finite]
        held_out = {
            fold: _with_column(sums[fold], fold_base, fold_target, column[rows])
            for fold, (rows, fold_base, fold_target) in parts.items()
        }
        total = sum(held_out.values())
        squared = 0.0
        for fold in used:
            trained = total - held_out[fold]
            squared += _held_out_squares(trained, held_out[fold], n_base + 1)
        rmse.append(math.sqrt(max(squared, 0.0) / (len(base) * n_outputs)))
    return np.asarray(rmse)


def _products(base, target):
    """Sums of products of the columns ``[base, target]`` of one fold."""
    joined = np.column_stack([base, target])
    return joined.T @ joined


def _with_column(products, base, target, column):
    """The sums of products of ``[base, column, target]`` from those of ``[base, target]``."""
    n_base = base.shape[1]
    cross = np.concatenate([base.T @ column, [column @ column], target.T @ column])
    size = products.shape[0] + 1
    out = np.empty((size, size))
    order = [*range(n_base), *range(n_base + 1, size)]  # where [base, target] go
    out[np.ix_(order, order)] = products
    out[n_base, :] = out[:, n_base] = cross
    return out


def _held_out_squares(trained, held_out, n_inputs):
    """Sum of squared residuals on the held-out fold of the least-squares fit on the trained
    sums (inputs first, then the targets), a tiny ridge keeping it solvable."""
    gram, cross = trained[:n_inputs, :n_inputs], trained[:n_inputs, n_inputs:]
    ridge = 1e-9 * np.trace(gram) / n_inputs
    coef = np.linalg.solve(gram + ridge * np.eye(n_inputs), cross)
    inputs, outputs = held_out[:n_inputs, :n_inputs], held_out[:n_inputs, n_inputs:]
    squares = held_out[n_inputs:, n_inputs:]
    return float(np.trace(squares - 2.0 * coef.T @ outputs + coef.T @ inputs @ coef))


def restore_steering_features(params, n_features_in, feature_names_in=None):
    """A fitted :class:`SteeringFeatures` from its parameters and fitted facts (a step of the
    portable model file), refused as ``fit`` would refuse them."""
    step = SteeringFeatures(**params)
    validate_parameter_constraints(
        SteeringFeatures._parameter_constraints,
        step.get_params(deep=False),
        caller_name="SteeringFeatures",
    )
    step._check_parameters()
    for name in ("friction_velocity", "velocity_filter"):
        if params.get(name) == AUTO:
            raise ValueError(
                f"{name}='auto' is a setting to fit; a fitted step holds the chosen value."
            )
    step.friction_velocity_ = step.friction_velocity
    step.velocity_filter_ = None if step.friction_velocity is None else step.velocity_filter
    step.friction_search_ = None
    step.n_features_in_ = n_features_in
    if feature_names_in is not None:
        step.feature_names_in_ = np.asarray(feature_names_in, dtype=object)
    step._check_inputs()
    return step


def _takes_groups(step, method):
    """Whether ``step`` has ``method`` and that method takes ``groups``."""
    function = getattr(step, method, None)
    return function is not None and "groups" in inspect.signature(function).parameters


def _final_step_has(method):
    """``available_if`` check: the pipeline's last step has ``method``."""

    def check(pipeline):
        return hasattr(pipeline.steps[-1][1], method)

    return check


def _in_caller_order(layout, result):
    """A method's result (arrays, a tuple of them, or anything else) in the caller's rows."""
    if isinstance(result, tuple):
        return tuple(_in_caller_order(layout, part) for part in result)
    return layout.to_caller_order(result) if isinstance(result, np.ndarray) else result


def _n_rows(X):
    return X.shape[0] if hasattr(X, "shape") else len(X)


def _needs_recordings(step):
    """Whether the step's output depends on where recordings begin (a filter over the rows,
    or a choice of one)."""
    if not isinstance(step, SteeringFeatures) or step.velocity_filter is None:
        return False
    return step.velocity_filter != AUTO or step.sampling_period is not None


class TorquePipeline(PickleVersionMixin, Pipeline):
    """The :class:`~sklearn.pipeline.Pipeline` of :func:`make_torque_pipeline`: recordings
    given once reach every step that reads them.

    ``fit``, ``predict`` and ``score`` take ``groups`` (the recording id of every row), read
    the recordings once, and hand them to every step whose method takes them, with
    scikit-learn's metadata routing on or off; with routing off, a scikit-learn ``Pipeline``
    passes ``groups`` only to the steps named in ``<step>__groups`` at fit and to no
    transformer at predict, so a velocity filter would run across recordings. A
    ``<step>__groups`` that leaves out a step whose output depends on the recordings is
    refused, naming the step. Recordings in the
    index of a panel (:func:`skhmmgmr.datasets.to_panel`) reach every step as they are.

    The regressor's own methods are the pipeline's, with the regressor's signatures and the
    recordings handed on alike: :meth:`predict` with ``return_std``,
    :meth:`predict_state_proba`, :meth:`predict_ahead` and :meth:`adapt` (which adapts the
    regressor in place). :meth:`filter_stream` streams the sensed rows one at a time.

    Parameters are those of :class:`~sklearn.pipeline.Pipeline`.

    Examples
    --------
    >>> import numpy as np
    >>> from skhmmgmr import make_torque_pipeline
    >>> from skhmmgmr.datasets import FEATURE_NAMES, make_driving_protocol
    >>> data = make_driving_protocol(("defensive",), duration=10.0, sampling_rate=20.0)
    >>> X, y = data[list(FEATURE_NAMES)], data["driver_torque"]
    >>> pipe = make_torque_pipeline(2, velocity_filter=0.1, sampling_period=0.05, random_state=0)
    >>> pipe = pipe.fit(X, y, groups=data["recording"])
    >>> pipe.predict(X, groups=data["recording"]).shape
    (4800,)
    >>> estimate, std = pipe.predict(X, groups=data["recording"], return_std=True)
    >>> pipe.predict_state_proba(X, groups=data["recording"]).shape
    (4800, 2)
    """

    def fit(self, X, y=None, groups=None, **params):
        """Fit every step, ``groups`` handed to every step whose ``fit`` takes it.

        Parameters
        ----------
        X : DataFrame or array-like of shape (n_samples, n_features)
        y : array-like of shape (n_samples,) or (n_samples, n_outputs)
        groups : array-like of shape (n_samples,), default=None
            Recording id of every row.
        **params : dict
            As for :meth:`sklearn.pipeline.Pipeline.fit`.

        Returns
        -------
        self : TorquePipeline
        """
        if not params:  # (per-row fit parameters would need the rows' order too)
            layout = read_layout(X, groups, canonical=True)
            y = layout.to_filter_order(align_target(X, y, layout))
            X, groups = layout.to_filter_order(X), layout.handed_down()
        return super().fit(X, y, **self._fit_params(X, groups, params))

    def _fit_params(self, X, groups, params):
        if groups is not None:
            if _routing_enabled():
                return {**params, "groups": groups}
            for name, step in self.steps:
                if _takes_groups(step, "fit"):
                    params = {**params, f"{name}__groups": groups}
            return params
        given = [name for name, _ in self.steps if f"{name}__groups" in params]
        missing = [
            name
            for name, step in self.steps
            if _needs_recordings(step) and f"{name}__groups" not in params
        ]
        if given and missing and not has_recording_index(X):
            raise ValueError(
                f"The recordings (groups) reach the step(s) {given} but not {missing}, whose "
                "output depends on where each recording begins (a filter over the rows): pass "
                f"groups= to the pipeline itself, which hands them to every step, or give X the "
                "recordings in its index (skhmmgmr.datasets.to_panel)."
            )
        return params

    def _transformed(self, X, groups, with_final):
        """``X`` through the transformers (all steps with ``with_final``), ``groups`` handed
        to those whose ``transform`` takes it."""
        steps = self.steps if with_final else self.steps[:-1]
        for _, step in steps:
            if step is None or step == "passthrough":
                continue
            X = (
                step.transform(X, groups=groups)
                if _takes_groups(step, "transform")
                else (step.transform(X))
            )
        return X

    def predict(self, X, groups=None, **params):
        """The final step's prediction, ``groups`` handed to every step that takes it.

        Parameters
        ----------
        X : DataFrame or array-like of shape (n_samples, n_features)
        groups : array-like of shape (n_samples,), default=None
            Recording id of every row.
        **params : dict
            Passed to the final step's ``predict`` (such as ``return_std=True`` or ``time``,
            with metadata routing on or off).

        Returns
        -------
        y_pred : ndarray, or a tuple with ``return_std``
        """
        own = "return_std" in params or "time" in params  # the regressor's, not metadata
        if own or not _routing_enabled():
            return self._final_method("predict", X, groups, **params)
        layout = read_layout(X, groups)
        X, groups = layout.to_filter_order(X), layout.handed_down()
        extra = {} if groups is None else {"groups": groups}
        return _in_caller_order(layout, super().predict(X, **extra, **params))

    def _final_method(self, method, X, groups, *args, y=None, **params):
        """The final step's ``method`` on ``X`` through the transformers, the recordings read
        once and handed to every step that takes them; results in the caller's row order."""
        check_is_fitted(self)
        layout = read_layout(X, groups)
        if y is not None:
            args = (layout.to_filter_order(align_target(X, y, layout)), *args)
        if params.get("time") is not None:
            params["time"] = layout.to_filter_order(np.asarray(params["time"]))
        X, groups = layout.to_filter_order(X), layout.handed_down()
        return _in_caller_order(layout, self._final_on(method, X, groups, *args, **params))

    def _final_on(self, method, X, groups, *args, **params):
        """The final step's ``method`` on ``X`` through the transformers, ``groups`` handed
        to every step that takes it."""
        final = self.steps[-1][1]
        Xt = self._transformed(X, groups, False)
        if _takes_groups(final, method):
            params["groups"] = groups
        return getattr(final, method)(Xt, *args, **params)

    @available_if(_final_step_has("predict_state_proba"))
    def predict_state_proba(self, X, groups=None, time=None):
        """The regressor's filtered state probabilities given the inputs up to each row.

        ``X`` goes through the transformers first, ``groups`` handed to every step that
        takes it (with metadata routing on or off), as in :meth:`predict`.

        Parameters
        ----------
        X : DataFrame or array-like of shape (n_samples, n_features)
        groups : array-like of shape (n_samples,), default=None
            Recording id of every row.
        time : array-like of shape (n_samples,), default=None
            Optional time stamps, checked to increase within every recording.

        Returns
        -------
        alpha : ndarray of shape (n_samples, n_states)
            See :meth:`HMMGMRRegressor.predict_state_proba
            <skhmmgmr.HMMGMRRegressor.predict_state_proba>`.

        Examples
        --------
        >>> from skhmmgmr import make_torque_pipeline
        >>> from skhmmgmr.datasets import FEATURE_NAMES, make_lane_keeping
        >>> data = make_lane_keeping(30.0, sampling_rate=20.0, random_state=0)
        >>> X, y = data[list(FEATURE_NAMES)], data["driver_torque"]
        >>> pipe = make_torque_pipeline(n_states=2, random_state=0).fit(X, y)
        >>> pipe.predict_state_proba(X).sum(axis=1)[:3]
        array([1., 1., 1.])
        """
        return self._final_method("predict_state_proba", X, groups, time=time)

    @available_if(_final_step_has("predict_ahead"))
    def predict_ahead(
        self, X, steps, groups=None, time=None, *, state_output="marginal", return_std=False
    ):
        """The regressor's forecast of the outputs ``steps`` rows ahead.

        ``X`` goes through the transformers first, ``groups`` handed to every step that
        takes it (with metadata routing on or off), as in :meth:`predict`.

        Parameters
        ----------
        X : DataFrame or array-like of shape (n_samples, n_features)
        steps : int
            Horizon in rows (``seconds * sampling_rate``).
        groups : array-like of shape (n_samples,), default=None
            Recording id of every row.
        time : array-like of shape (n_samples,), default=None
        state_output : {"marginal", "conditional"}, default="marginal"
        return_std : bool, default=False
            Also return the predictive standard deviation.

        Returns
        -------
        y_pred : ndarray of shape (n_samples,) or (n_samples, n_outputs)
        y_std : ndarray of the same shape, only when ``return_std`` is True
            See :meth:`HMMGMRRegressor.predict_ahead <skhmmgmr.HMMGMRRegressor.predict_ahead>`.

        Examples
        --------
        >>> import numpy as np
        >>> from skhmmgmr import make_torque_pipeline
        >>> from skhmmgmr.datasets import FEATURE_NAMES, make_lane_keeping
        >>> data = make_lane_keeping(30.0, sampling_rate=20.0, random_state=0)
        >>> X, y = data[list(FEATURE_NAMES)], data["driver_torque"]
        >>> pipe = make_torque_pipeline(n_states=2, random_state=0).fit(X, y)
        >>> bool(np.allclose(pipe.predict_ahead(X, 0), pipe.predict(X)))
        True
        >>> pipe.predict_ahead(X, 10).shape  # the torque half a second ahead
        (600,)
        """
        return self._final_method(
            "predict_ahead",
            X,
            groups,
            steps,
            time=time,
            state_output=state_output,
            return_std=return_std,
        )

    @available_if(_final_step_has("adapt"))
    def adapt(self, X, y, groups=None, *, relevance=256.0, parameters="mv", n_iter=10, time=None):
        """Adapt the fitted regressor to new recordings (MAP EM); the transformers stay.

        ``X`` goes through the transformers first, ``groups`` handed to every step that
        takes it (with metadata routing on or off), then the regressor adapts as
        :meth:`HMMGMRRegressor.adapt <skhmmgmr.HMMGMRRegressor.adapt>` does, in place.

        Parameters
        ----------
        X : DataFrame or array-like of shape (n_samples, n_features)
            Inputs of the new recordings.
        y : array-like of shape (n_samples,) or (n_samples, n_outputs)
        groups : array-like of shape (n_samples,), default=None
            Recording id of every row.
        relevance : float, default=256.0
            Relevance factor ``r`` > 0: rows of evidence at which a state moves halfway.
        parameters : str, default="mv"
            Which parameters adapt: any of "m" (means), "v" (covariances), "t" (transitions).
        n_iter : int, default=10
            Maximum number of MAP EM iterations.
        time : array-like of shape (n_samples,), default=None
            Optional time stamps, checked to increase within every recording.

        Returns
        -------
        self : TorquePipeline
            With the regressor adapted (a new ``model_``, the previous one not modified; no
            rows leave it unchanged).

        Examples
        --------
        >>> from skhmmgmr import make_torque_pipeline
        >>> from skhmmgmr.datasets import FEATURE_NAMES, make_lane_keeping
        >>> data = make_lane_keeping(30.0, sampling_rate=20.0, random_state=0)
        >>> X, y = data[list(FEATURE_NAMES)], data["driver_torque"]
        >>> pipe = make_torque_pipeline(n_states=2, random_state=0).fit(X, y)
        >>> fitted = pipe[-1].model_
        >>> adapted = pipe.adapt(X[:200], y[:200] + 0.2, relevance=8.0)  # another driver
        >>> bool(adapted is pipe and pipe[-1].model_ is not fitted)
        True
        """
        options = {"relevance": relevance, "parameters": parameters, "n_iter": n_iter}
        if _n_rows(X) == 0:  # nothing to derive: the regressor checks y and groups, keeps its model
            check_is_fitted(self)
            self.steps[-1][1].adapt(X, y, groups=groups, time=time, **options)
            return self
        self._final_method("adapt", X, groups, y=y, time=time, **options)
        return self

    def filter_stream(self, **kwargs):
        """Sample-by-sample causal filter of the whole pipeline for real-time use.

        Parameters
        ----------
        **kwargs : dict
            Passed to :class:`~skhmmgmr.FilterStream` (``relevance``...; ``missing_values``
            and ``min_log_density`` default to the regressor's).

        Returns
        -------
        stream : FilterStream
            Call ``stream.update(row)`` with every sensed row (in the pipeline's input order,
            or by name) and ``stream.reset()`` at the start of every recording; the derived
            inputs are computed in the stream, and the estimates equal those of
            :meth:`predict`.

        Examples
        --------
        >>> import numpy as np
        >>> from skhmmgmr import make_torque_pipeline
        >>> from skhmmgmr.datasets import FEATURE_NAMES, make_lane_keeping
        >>> data = make_lane_keeping(30.0, sampling_rate=20.0, random_state=0)
        >>> X, y = data[list(FEATURE_NAMES)], data["driver_torque"]
        >>> pipe = make_torque_pipeline(n_states=2, velocity_filter=0.1, sampling_period=0.05,
        ...                             random_state=0).fit(X, y)
        >>> stream = pipe.filter_stream()
        >>> estimates = [stream.update(row) for row in X.to_numpy()[:100]]
        >>> bool(np.allclose(estimates, pipe.predict(X[:100]), rtol=0, atol=1e-12))
        True
        """
        return FilterStream(self, **kwargs)

    def score(self, X, y=None, sample_weight=None, groups=None, **params):
        """The final step's score, ``groups`` handed to every step that takes it.

        Parameters
        ----------
        X : DataFrame or array-like of shape (n_samples, n_features)
        y : array-like of shape (n_samples,) or (n_samples, n_outputs)
        sample_weight : array-like of shape (n_samples,), default=None
        groups : array-like of shape (n_samples,), default=None
            Recording id of every row.
        **params : dict
            As for :meth:`sklearn.pipeline.Pipeline.score`.

        Returns
        -------
        score : float
        """
        layout = read_layout(X, groups)
        X, y, groups = layout.to_filter_order(X), layout.to_filter_order(y), layout.handed_down()
        sample_weight = layout.to_filter_order(sample_weight)
        if groups is None or _routing_enabled():
            extra = {} if groups is None else {"groups": groups}
            return super().score(X, y, sample_weight=sample_weight, **extra, **params)
        check_is_fitted(self)
        final = self.steps[-1][1]
        weights = {} if sample_weight is None else {"sample_weight": sample_weight}
        return final.score(self._transformed(X, groups, False), y, groups=groups, **weights)


def _check_regressor_params(params, caller, own):
    """Refuse a factory's ``params`` that are not :class:`~skhmmgmr.HMMGMRRegressor`'s,
    naming the factory (``caller``) and its own parameters (``own``)."""
    accepted = HMMGMRRegressor().get_params()
    unknown = sorted(set(params) - set(accepted))
    if unknown:
        raise TypeError(
            f"{caller} got unknown parameter(s) {unknown}; it takes {own} and "
            f"HMMGMRRegressor's parameters {sorted(accepted)}."
        )


@fill_shared_parameters
def make_torque_pipeline(
    n_states=5,
    *,
    friction_velocity="auto",
    load_columns=("steering_wheel_angle", "lateral_acceleration"),
    powers=(2, 3),
    velocity_filter="auto",
    sampling_period=None,
    output_smoothing="auto",
    **params,
):
    """HMM-GMR behind the steering system's derived inputs: a scikit-learn ``Pipeline``.

    The pipeline is ``SteeringFeatures`` (step ``"steering_features"``) then
    :class:`~skhmmgmr.HMMGMRRegressor` (step ``"hmmgmr"``). It takes data frames with the
    package's column names (:data:`skhmmgmr.datasets.FEATURE_NAMES`); recordings reach both
    steps in the index of a panel (:func:`skhmmgmr.datasets.to_panel`), or as ``groups=`` given
    to the pipeline's ``fit``, ``predict`` and ``score`` (:class:`TorquePipeline`), with
    metadata routing on or off. ``hmmgmr__groups=`` alone is refused with ``velocity_filter``:
    the filter of ``SteeringFeatures`` would run across recordings. On the simulator's
    protocol it is more accurate than a default gradient-boosting regressor and
    smoother (see "When to use HMM-GMR" in the user guide, and
    ``benchmarks/bench_baselines.py``).

    Parameters
    ----------
    n_states : int, default=5
        Number of hidden states of the regressor; choose it on validation recordings
        (:class:`~skhmmgmr.StateSelector`, or a ``GridSearchCV`` over ``hmmgmr__n_states``).
    friction_velocity, load_columns, powers, velocity_filter
        Passed to :class:`SteeringFeatures`. By default (``"auto"``) the friction band and the
        velocity filter are chosen in ``fit`` on the training recordings
        (``pipeline[0].friction_search_``), so that they suit the car; the filter is
        considered only with ``sampling_period``, which should therefore be given (at 100 Hz
        the filter keeps the velocity sensor's noise out of the friction input). The
        recordings reach the transformer through ``groups`` given to the pipeline or a panel
        index.
    {sampling_period}
    output_smoothing : None, float >= 0 or "auto", default="auto"
        Passed to :class:`~skhmmgmr.HMMGMRRegressor`: the causal first-order read-out of
        the estimate. By default the weakest whose estimate of the training recordings is no
        rougher than the measured torque there (``pipeline[-1].output_smoothing_``, in rows;
        0 when the estimate already is not); None: the filter's estimate itself.
    **params
        Any other parameter of :class:`~skhmmgmr.HMMGMRRegressor` (``random_state``,
        ``covariance_type``, ``missing_values``...).

    Returns
    -------
    pipeline : TorquePipeline
        A scikit-learn ``Pipeline``, unfitted; ``pipeline[-1]`` is the regressor. ``groups``
        given to its ``fit``, ``predict`` and ``score`` reach both steps.

    Examples
    --------
    >>> from skhmmgmr import make_torque_pipeline
    >>> from skhmmgmr.datasets import FEATURE_NAMES, make_lane_keeping
    >>> data = make_lane_keeping(30.0, sampling_rate=20.0, random_state=0)
    >>> model = make_torque_pipeline(n_states=2, random_state=0)
    >>> model = model.fit(data[list(FEATURE_NAMES)], data["driver_torque"])
    >>> model.predict(data[list(FEATURE_NAMES)]).shape
    (600,)
    """
    _check_regressor_params(
        params,
        "make_torque_pipeline",
        "n_states, friction_velocity, load_columns, powers, velocity_filter, sampling_period, "
        "output_smoothing",
    )
    return TorquePipeline(
        [
            (
                "steering_features",
                SteeringFeatures(
                    friction_velocity=friction_velocity,
                    load_columns=load_columns,
                    powers=powers,
                    velocity_filter=velocity_filter,
                    sampling_period=sampling_period,
                ),
            ),
            (
                "hmmgmr",
                HMMGMRRegressor(n_states=n_states, output_smoothing=output_smoothing, **params),
            ),
        ]
    )


# --------------------------------------------------------------------------------------------
# The driver model: the torque pipeline fitted on perturbation experiments, so that it drives
# --------------------------------------------------------------------------------------------

#: ``perturbation_penalty`` of :func:`make_driver_model` by default, measured by
#: ``benchmarks/bench_driver_model.py`` (the frontier of accuracy and driving).
DEFAULT_PERTURBATION_PENALTY = 1.5


class DriverModel(TorquePipeline):
    """The torque pipeline of :func:`make_driver_model`: fitted on recordings with a
    perturbation experiment, so that it estimates the driver's torque and drives the car.

    Regressed on the steering wheel's and the vehicle's own states, a model of the driver's
    torque learns mostly the steering system's inverse (the torque that holds the wheel where
    it is), a positive feedback at the wheel. In the recordings of a perturbation experiment
    (:func:`skhmmgmr.datasets.make_driving_protocol` with ``perturbation=``) a torque that the
    driver does not know pushes the wheel: the inverse would follow it, the driver's torque
    does not. ``fit`` penalises the estimate's covariance with that torque, by
    ``perturbation_penalty``: it minimises

    ``sum_t (y_t - f(x_t))^2 + 2 * perturbation_penalty * sum_t p_t f(x_t)``

    over the training rows (``p``: the perturbation), which is the least-squares fit of
    ``y - perturbation_penalty * p``; the model is fitted on that target. The larger the
    penalty, the less the model leans on the wheel's response to a torque at the wheel, and
    the more on what the driver sees: the steadier it drives, the less accurately it
    estimates recorded torque. Without perturbed training rows the penalty does nothing and
    the model is a torque pipeline.

    Everything but ``fit`` is :class:`TorquePipeline`'s: ``predict``, the stream, the model
    file, the C code and the simulator's :func:`~skhmmgmr.datasets.drive` never need the
    perturbation.

    Parameters
    ----------
    steps : list of (str, estimator) tuples
        As for :class:`~sklearn.pipeline.Pipeline` (``SteeringFeatures`` steps then the
        regressor, as :func:`make_driver_model` builds them).
    perturbation_penalty : float >= 0, default=1.5
        The trade-off: how much ``fit`` keeps the estimate from following the perturbation's
        push on the wheel (see above), in multiples of the perturbation. 0: the plain fit of
        the recordings.
    transform_input, memory, verbose
        As for :class:`~sklearn.pipeline.Pipeline`.

    Attributes
    ----------
    perturbation_rms_ : float
        RMS [Nm] of the perturbation over the perturbed training rows (0 without any).
    perturbed_share_ : float
        Share of the training rows with a perturbation.

    See Also
    --------
    make_driver_model : Build one.
    skhmmgmr.datasets.make_driving_protocol : Recordings with a perturbation experiment.
    """

    _parameter_constraints = {
        **Pipeline._parameter_constraints,
        "perturbation_penalty": [Interval(numbers.Real, -1, None, closed="left")],
    }

    def __init__(
        self,
        steps,
        *,
        perturbation_penalty=DEFAULT_PERTURBATION_PENALTY,
        transform_input=None,
        memory=None,
        verbose=False,
    ):
        super().__init__(steps, transform_input=transform_input, memory=memory, verbose=verbose)
        self.perturbation_penalty = perturbation_penalty

    def fit(self, X, y=None, groups=None, perturbation=None, **params):
        """Fit every step on the penalised target ``y - perturbation_penalty * perturbation``.

        Parameters
        ----------
        X : DataFrame or array-like of shape (n_samples, n_features)
            Sensed inputs (the perturbation is not one of them).
        y : array-like of shape (n_samples,) or (n_samples, 1)
            The driver's torque.
        groups : array-like of shape (n_samples,), default=None
            Recording id of every row.
        perturbation : array-like of shape (n_samples,), default=None
            The torque [Nm] of the perturbation experiment at every row, in the rows of ``y``
            (the column ``steering_perturbation`` of the simulator's frames); 0 where a
            recording had none. None: no perturbation (the penalty does nothing).
        **params : dict
            As for :meth:`TorquePipeline.fit`.

        Returns
        -------
        self : DriverModel
        """
        self._validate_params()
        penalised = self._penalised_target(y, perturbation)
        return super().fit(X, penalised, groups=groups, **params)

    def _penalised_target(self, y, perturbation):
        """``y - perturbation_penalty * perturbation``, with the fitted facts of the
        perturbation; ``y`` as it was (a pandas object keeps its index)."""
        self.perturbation_rms_, self.perturbed_share_ = 0.0, 0.0
        if perturbation is None or y is None:
            return y
        torque = np.asarray(perturbation, dtype=float)
        n_rows = _n_rows(y)
        if torque.ndim != 1 or torque.shape[0] != n_rows:
            raise ValueError(
                f"perturbation has shape {torque.shape}; fit needs one torque [Nm] per row of "
                f"y, shape ({n_rows},)."
            )
        bad = np.flatnonzero(~np.isfinite(torque))
        if bad.size:
            raise ValueError(
                f"perturbation is {torque[bad[0]]} in row {bad[0]}; it must be a finite torque "
                "[Nm] on every row (0 where a recording had no perturbation)."
            )
        pushed = torque != 0.0
        if pushed.any():
            self.perturbation_rms_ = float(np.sqrt(np.mean(torque[pushed] ** 2)))
            self.perturbed_share_ = float(pushed.mean())
        if self.perturbation_penalty == 0 or not pushed.any():
            return y
        if np.ndim(y) == 2 and np.shape(y)[1] != 1:
            raise ValueError(
                f"y has {np.shape(y)[1]} outputs; the perturbation penalises one, the driver's "
                "torque."
            )
        shift = self.perturbation_penalty * torque
        if isinstance(y, pd.DataFrame):
            return y.sub(shift, axis=0)
        if isinstance(y, pd.Series):
            return y - shift
        y = np.asarray(y, dtype=float)
        return y - (shift[:, None] if y.ndim == 2 else shift)


@fill_shared_parameters
def make_driver_model(
    n_states=1,
    *,
    perturbation_penalty=DEFAULT_PERTURBATION_PENALTY,
    friction_velocity="auto",
    friction_column="steering_wheel_velocity",
    load_columns=("steering_wheel_angle", "lateral_acceleration"),
    powers=(2,),
    velocity_filter="auto",
    sampling_period=None,
    output_smoothing="auto",
    random_state=None,
    **params,
):
    """A driver model that estimates the recorded torque and drives the car.

    The torque pipeline (derived steering-system inputs, then
    :class:`~skhmmgmr.HMMGMRRegressor`) fitted, as a :class:`DriverModel`, on recordings of
    which some carry a perturbation experiment: a torque on the steering wheel that the
    driver does not know (:func:`skhmmgmr.datasets.make_driving_protocol` with
    ``perturbation=``; ``fit(..., perturbation=frame["steering_perturbation"])``). The
    perturbation shows which part of the wheel's motion the driver did not cause; fitted with
    the penalty ``perturbation_penalty`` on following it, the model leans less on the steering
    system's inverse (a positive feedback at the wheel, by which the torque pipeline weaves
    through the lane and leaves it) and more on what the driver sees.

    Fit it on :data:`~skhmmgmr.datasets.DRIVER_MODEL_FEATURES` (every sensed feature but the
    steering wheel's acceleration, whose twice-differentiated, delayed measurement makes a
    model at the wheel oscillate at 20 Hz); it takes any named sensed columns.

    Parameters
    ----------
    n_states : int, default=1
        Hidden states of the regressor. One state (a linear regression on the sensed and
        derived inputs) drives most steadily and, on the perturbed recordings, estimates as
        well as three: on the simulator, three states estimated 0.2-1.3 points worse and left
        the road more often (``benchmarks/bench_driver_model.py``).
    perturbation_penalty : float >= 0, default=1.5
        The trade-off between the open-loop accuracy and the driving: how much ``fit`` keeps
        the estimate from following the perturbation's push on the wheel (see
        :class:`DriverModel`), in multiples of the perturbation. 0: the plain fit of the
        perturbed recordings. The default is the smallest value at which the model kept
        control on every held-out road of the simulator's three styles at 20 and 100 Hz,
        trained with a 0.1 Nm perturbation in every training recording (the frontier and
        the targets are in the user guide's "The driver model at the wheel"); choose it for
        your data with :func:`skhmmgmr.selection.make_closed_loop_scorer`.
    friction_velocity, friction_column, load_columns, powers, velocity_filter
        Passed to :class:`SteeringFeatures` (see :func:`make_torque_pipeline`). The load's
        signed square only (``powers=(2,)``): a cube makes the torque grow without bound
        with the wheel's angle, which at the wheel runs away on sharp curves.
    {sampling_period}
    output_smoothing : None, float >= 0 or "auto", default="auto"
        Passed to :class:`~skhmmgmr.HMMGMRRegressor` (see :func:`make_torque_pipeline`).
    random_state : int, RandomState instance or None, default=None
        Passed to :class:`~skhmmgmr.HMMGMRRegressor`.
    **params
        Any other parameter of :class:`~skhmmgmr.HMMGMRRegressor`.

    Returns
    -------
    model : DriverModel
        A scikit-learn ``Pipeline`` (a :class:`TorquePipeline`), unfitted.

    See Also
    --------
    make_torque_pipeline : The most accurate estimate of the recorded torque, which does not
        drive.
    skhmmgmr.datasets.drive : The model at the simulator's wheel.

    Examples
    --------
    >>> from skhmmgmr import make_driver_model
    >>> from skhmmgmr.datasets import DRIVER_MODEL_FEATURES, make_driving_protocol
    >>> data = make_driving_protocol(("defensive",), n_train_per_setting=1, n_validation=0,
    ...                              n_test=1, duration=30.0, sampling_rate=20.0,
    ...                              random_state=0, perturbation=0.1)
    >>> train, test = data[data["split"] == "train"], data[data["split"] == "test"]
    >>> features = list(DRIVER_MODEL_FEATURES)
    >>> model = make_driver_model(sampling_period=0.05, random_state=0).fit(
    ...     train[features], train["driver_torque"], groups=train["recording"],
    ...     perturbation=train["steering_perturbation"])
    >>> round(model.perturbation_rms_, 3), model.perturbed_share_
    (0.1, 1.0)
    >>> model.predict(test[features], groups=test["recording"]).shape
    (600,)
    """
    _check_regressor_params(
        params,
        "make_driver_model",
        "n_states, perturbation_penalty, friction_velocity, friction_column, load_columns, "
        "powers, velocity_filter, sampling_period, output_smoothing",
    )
    pipeline = make_torque_pipeline(
        n_states,
        friction_velocity=friction_velocity,
        load_columns=load_columns,
        powers=powers,
        velocity_filter=velocity_filter,
        sampling_period=sampling_period,
        output_smoothing=output_smoothing,
        random_state=random_state,
        **params,
    )
    pipeline.steps[0][1].set_params(friction_column=friction_column)
    return DriverModel(pipeline.steps, perturbation_penalty=perturbation_penalty)
