"""``SteeringFeatures``: the derived inputs of a power-assisted steering system as a
scikit-learn transformer.

Each derived input (``_derived_inputs.py``: the friction input and the signed powers of the
load's proxies) is an ordinary named column: the transformer appends them to a data frame, so
the selection framework keeps or drops them like any other feature. Its only learned settings
are the ``"auto"`` ones (the friction inputs, one band or a basis of several, and the
velocity filter), chosen in ``fit`` by ``_friction_search.py``, and the sampling period of
the velocity filter, read from the time index of the training recordings when it is not
given.
"""

import numbers

import numpy as np
import pandas as pd
from sklearn.base import BaseEstimator, TransformerMixin
from sklearn.utils.validation import check_is_fitted, validate_data

from .._core._compat import Interval, StrOptions, _fit_context, validate_parameter_constraints
from .._core._docstrings import fill_shared_parameters
from .._core._panel import in_filter_order
from .._core._pickled import PickleVersionMixin
from .._core._sequences import median_time_step
from ._derived_inputs import (
    SLOW_FRICTION_NAME,
    check_settings,
    derived_names,
    derived_units,
    filtered_velocity,
    fitted_friction,
    fitted_lead,
    fitted_radii,
    fitted_slow,
    friction_inputs,
    hysteresis_names,
    led_angle,
    load_inputs,
    recording_hysteresis,
    source_positions,
    stream_description,
)
from ._friction_search import AUTO, RADIUS_GRID, WIDTH_GRID, candidate_table

AUTO_OPTION = StrOptions({AUTO})
#: The settings ``fit`` may choose.
LEARNED = (
    "friction_velocity",
    "velocity_filter",
    "friction_angle",
    "angle_lead",
    "slow_velocity_filter",
)


@fill_shared_parameters
class SteeringFeatures(PickleVersionMixin, TransformerMixin, BaseEstimator):
    """Append the friction and load-compression inputs of a power-assisted steering system.

    Only the ``"auto"`` settings are learned: ``fit`` chooses the friction inputs (no band, one
    band or a basis of several, their widths read from the velocity's own scale), the
    hysteresis inputs and the velocity filter on the target by a grouped inner validation (see
    ``friction_search_`` and the user guide). Without a velocity filter and hysteresis inputs
    the transform is row by row, so it is causal and streams: the same row always gives the
    same derived inputs. With them, the friction inputs read the velocity through a causal
    first-order filter, and the hysteresis inputs the angle through plays, both restarted at
    every recording (the recordings come from ``groups`` or from the index of a panel,
    :func:`skhmmgmr.datasets.to_panel`; without either, the rows form one recording in time
    order). Missing values (NaN) stay missing.

    Parameters
    ----------
    friction_velocity : float, tuple of float, "auto" or None, default=0.1
        Steering-wheel velocity [rad/s] over which Coulomb friction changes sign; the derived
        input ``steering_friction`` is ``tanh(velocity / friction_velocity)``. A tuple of
        widths ``w_j`` is a basis of friction inputs ``tanh(velocity / w_j)``, named
        ``steering_friction_<w_j>`` (``w_j`` to three significant digits), whose combination
        each state's regression fits: a friction curve of any sharpness within the widths.
        ``"auto"``: chosen in ``fit`` (which then needs ``y``) by the held-out error of a
        least-squares fit, among no friction input and every run of consecutive widths of a
        ladder a factor 2 apart, from the narrowest the (filtered) velocity resolves to the
        widest the data needs (``_friction_search.py``; the fewest inputs within 0.2 % of the
        least error); one width chosen is the tuple of that width. ``None`` adds no friction
        input.
    friction_angle : float, tuple of float, "auto" or None, default=None
        Half-widths ``r`` [rad] of plays on the steering-wheel angle: the hysteresis inputs
        ``steering_hysteresis_<r> = (angle - p) / r`` in [-1, 1], the play ``p`` following the
        angle at most ``r`` behind it (``p_t = clip(p_(t-1), angle_t - r, angle_t + r)``,
        started at each recording's first observed angle): the angle turned since the last
        reversal, over which a column whose friction sticks twists before it slips (the
        hysteresis of torque against angle). ``"auto"``: chosen in ``fit`` with the friction
        inputs, among none and every run of consecutive half-widths of a ladder a factor 2
        apart from the angle's resolution up to the angle's excursions (``_friction_search.py``).
        A missing angle gives missing hysteresis inputs and leaves the plays alone.
    angle_column : str or int, default="steering_wheel_angle"
        The column holding the steering-wheel angle, for ``friction_angle``.
    angle_lead : float, "auto" or None, default=None
        The plays follow ``angle + angle_lead * velocity`` (``friction_column``, unfiltered):
        the velocity places an angle sensor's coarse steps (0.1 deg) within the twist of a
        column that sticks. ``"auto"``: none, 0.02 or 0.05 s (``ANGLE_LEADS``), chosen in
        ``fit`` with the plays. ``None`` (or 0): the angle itself.
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
        filters nothing. A time constant needs the sampling period (``sampling_period``, or
        the time index of the training rows). ``"auto"``: none, 0.02 or 0.05 s
        (``FILTER_CANDIDATES``), chosen in ``fit`` with the friction inputs (no filter without
        a sampling period; none with no friction input). The filter starts at the first observed
        velocity of each recording (its output equals it there); a missing velocity gives a
        missing friction input and leaves the filter's state alone, and the next observed
        velocity is taken in over the whole time since the last one.
    slow_velocity_filter : float, "auto" or None, default=None
        Time constant [s] of a second causal first-order low-pass filter on the (unfiltered)
        velocity, with its own state: the friction inputs of that slow velocity,
        ``steering_friction_slow`` (one band) or ``steering_friction_slow_<w_j>`` (a basis),
        of the same widths as the friction inputs, follow a column whose friction lags the
        wheel. Started, restarted and kept over missing velocities as ``velocity_filter``;
        it needs the sampling period too. ``"auto"``: none, 0.1 or 0.2 s
        (``SLOW_FILTER_CANDIDATES``), chosen in ``fit`` with the friction inputs (none
        without a sampling period or a friction input). ``None``: no such inputs.
    {sampling_period}
        ``None``: read in ``fit`` from the ``time`` level of the index of ``X`` (a panel) when
        a velocity filter needs it, as the median step between consecutive rows of a
        recording (the command line infers it alike); without a time level a filter is not
        considered.

    Attributes
    ----------
    friction_velocity_ : float, tuple of float or None
        The friction band or basis widths the transform uses: ``friction_velocity``, or the
        ones chosen (a tuple, ``None`` for no friction input).
    friction_angle_ : tuple of float or None
        The plays' half-widths the transform uses: ``friction_angle`` (one number as a tuple of
        one), or the ones chosen (``None``: no hysteresis input).
    velocity_filter_ : float or None
        The velocity filter's time constant the transform uses (``None``: no filter).
    angle_lead_ : float or None
        The plays' lead on the velocity [s] (``None``: the angle itself, or no plays).
    slow_velocity_filter_ : float or None
        The slow velocity filter's time constant the transform uses (``None``: no friction
        inputs of a slow velocity).
    sampling_period_ : float or None
        The seconds between two rows the velocity filter uses: ``sampling_period``, or the
        one read from the time index in ``fit`` (``None``: unknown).
    friction_search_ : DataFrame or None
        The ``"auto"`` choice: one row per candidate, with ``friction_velocity`` (a width, a
        tuple of widths or None), ``friction_angle`` (a tuple of half-widths or None),
        ``velocity_filter``, ``angle_lead``, ``slow_velocity_filter``, ``n_friction_inputs``
        (friction and hysteresis inputs), ``validation_rmse`` (held-out root mean squared
        error of the linear fit, in the target's unit) and ``chosen``; ``None`` without an
        ``"auto"`` setting.
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

    A basis of friction widths:

    >>> basis = SteeringFeatures(friction_velocity=(0.01, 0.1)).fit_transform(X)
    >>> list(basis.columns[3:5])
    ['steering_friction_0.01', 'steering_friction_0.1']

    With ``"auto"`` (the default of :func:`make_torque_pipeline`) ``fit`` chooses them on the
    torque:

    >>> from skhmmgmr.datasets import FEATURE_NAMES, make_lane_keeping
    >>> data = make_lane_keeping(60.0, sampling_rate=20.0, random_state=0)
    >>> step = SteeringFeatures(friction_velocity="auto", velocity_filter="auto")
    >>> step = step.fit(data[list(FEATURE_NAMES)], data["driver_torque"])
    >>> step.friction_velocity_, step.velocity_filter_
    ((0.1,), None)
    """

    _parameter_constraints = {
        "friction_velocity": [
            Interval(numbers.Real, 0, None, closed="neither"),
            StrOptions({AUTO}),
            tuple,
            list,
            None,
        ],
        "friction_column": [str, Interval(numbers.Integral, 0, None, closed="left")],
        "friction_angle": [
            Interval(numbers.Real, 0, None, closed="neither"),
            StrOptions({AUTO}),
            tuple,
            list,
            None,
        ],
        "angle_column": [str, Interval(numbers.Integral, 0, None, closed="left")],
        "load_columns": [tuple, list],
        "powers": [tuple, list],
        "velocity_filter": [
            Interval(numbers.Real, 0, None, closed="neither"),
            StrOptions({AUTO}),
            None,
        ],
        "sampling_period": [Interval(numbers.Real, 0, None, closed="neither"), None],
        "angle_lead": [Interval(numbers.Real, None, None, closed="neither"), AUTO_OPTION, None],
        "slow_velocity_filter": [
            Interval(numbers.Real, 0, None, closed="neither"),
            AUTO_OPTION,
            None,
        ],
    }

    def __init__(
        self,
        friction_velocity=0.1,
        friction_column="steering_wheel_velocity",
        load_columns=("steering_wheel_angle", "lateral_acceleration"),
        powers=(2, 3),
        velocity_filter=None,
        sampling_period=None,
        friction_angle=None,
        angle_column="steering_wheel_angle",
        angle_lead=None,
        slow_velocity_filter=None,
    ):
        self.friction_velocity = friction_velocity
        self.friction_column = friction_column
        self.load_columns = load_columns
        self.powers = powers
        self.velocity_filter = velocity_filter
        self.sampling_period = sampling_period
        self.friction_angle = friction_angle
        self.angle_column = angle_column
        self.angle_lead = angle_lead
        self.slow_velocity_filter = slow_velocity_filter

    __metadata_request__fit = {"groups": True}
    __metadata_request__transform = {"groups": True}

    def __setstate__(self, state):
        # a step pickled before sampling_period_ existed filtered with sampling_period
        if "n_features_in_" in state and "sampling_period_" not in state:
            state = {**state, "sampling_period_": state.get("sampling_period")}
        # one pickled before the hysteresis inputs existed had none
        state = {"friction_angle": None, "angle_column": "steering_wheel_angle", **state}
        state = {"angle_lead": None, "slow_velocity_filter": None, **state}
        for name in ("friction_angle_", "angle_lead_", "slow_velocity_filter_"):
            if "n_features_in_" in state and name not in state:
                state[name] = None
        super().__setstate__(state)

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
            recordings, and the velocity filter and the plays restart at each. ``None``: the
            index's recording level if any, else one recording.

        Returns
        -------
        self : SteeringFeatures
            The fitted transformer.
        """
        self._check_parameters()
        values = validate_data(self, X, ensure_all_finite="allow-nan", reset=True)
        self.friction_velocity_ = fitted_friction(self.friction_velocity)
        self.friction_angle_ = fitted_radii(self.friction_angle)
        self.angle_lead_ = fitted_lead(self.angle_lead, self.friction_angle_)
        self.slow_velocity_filter_ = fitted_slow(self.slow_velocity_filter, self.friction_velocity)
        self._check_inputs()
        self.velocity_filter_ = None if self.friction_velocity is None else self.velocity_filter
        self.sampling_period_ = self.sampling_period
        self.friction_search_ = None
        searched = AUTO in self._learned()
        if searched and y is None:
            raise ValueError(
                f"{self._settings()}: an 'auto' setting is chosen on the target, so fit needs "
                "y (the torque)."
            )
        needs_period = bool(self._filters()) and self.sampling_period is None
        if searched or needs_period:
            target = y if searched else None
            in_filter_order(self._fit_in_filter_order, X, groups, y=target, rows={"values": values})
        return self

    def _fit_in_filter_order(self, layout, X, values, y=None):
        """The learned settings from rows in filter order and their recordings' ``layout``:
        the sampling period (when a filter needs it), then the ``"auto"`` choice."""
        if self._filters() and self.sampling_period_ is None:
            if layout.time is not None:
                layout.recordings(len(values))  # the time checked to increase first
                self.sampling_period_ = median_time_step(layout.time, layout.groups)
            fixed = [name for name in self._filters() if getattr(self, name) != AUTO]
            if fixed and self.sampling_period_ is None:
                raise ValueError(
                    f"{fixed[0]}={getattr(self, fixed[0])!r} needs sampling_period (the "
                    "seconds between two rows), or X with a 'time' index level to read it "
                    "from; got sampling_period=None."
                )
        if AUTO not in self._learned():
            return
        self.friction_search_ = candidate_table(
            self, layout, values, y, source_positions(self), self._settings()
        )
        chosen = self.friction_search_[self.friction_search_["chosen"]].iloc[0]
        self.friction_velocity_ = fitted_friction(chosen["friction_velocity"])
        self.friction_angle_ = fitted_radii(chosen["friction_angle"])
        self.velocity_filter_ = chosen["velocity_filter"]
        self.angle_lead_ = fitted_lead(chosen["angle_lead"], self.friction_angle_)
        self.slow_velocity_filter_ = fitted_slow(
            chosen["slow_velocity_filter"], self.friction_velocity_
        )
        if self.friction_velocity_ is None:
            self.velocity_filter_ = None
        elif self.velocity_filter_ is not None:
            self.velocity_filter_ = float(self.velocity_filter_)

    def _filters(self):
        """The velocity filters the fitted step runs (or may choose), by parameter name."""
        return [
            name
            for name in ("velocity_filter", "slow_velocity_filter")
            if getattr(self, f"{name}_") is not None
        ]

    def _learned(self):  # the settings fit may choose ("auto" before the choice)
        return tuple(getattr(self, f"{name}_") for name in LEARNED)

    def _settings(self):
        """The settings searched, as the errors name them."""
        return (
            f"friction_velocity={self.friction_velocity!r}, "
            f"velocity_filter={self.velocity_filter!r}, "
            f"friction_angle={self.friction_angle!r}, angle_lead={self.angle_lead!r}, "
            f"slow_velocity_filter={self.slow_velocity_filter!r}"
        )

    def _check_parameters(self):  # what the parameters' constraints cannot say
        check_settings(self)

    def _check_inputs(self):
        """The fitted inputs hold the source columns and none of the derived ones."""
        source_positions(self)
        inputs = [str(name) for name in getattr(self, "feature_names_in_", ())]
        taken = [name for name in self._derived_names() if name in inputs]
        if taken:
            raise ValueError(
                f"X already has the column(s) {taken}, which SteeringFeatures derives: rename "
                "them, or leave their source out (friction_velocity=None for the friction "
                "input, friction_angle=None for the hysteresis inputs, load_columns or powers "
                "for the others)."
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
            Recording id of every row, for ``velocity_filter``, ``friction_angle`` and the
            ``"auto"`` choice.

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
            Recording id of every row, for ``velocity_filter`` and ``friction_angle`` (the
            filter and the plays restart at every recording; the rows of a recording
            contiguous and in time order, unless the
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
        positions = source_positions(self)
        derived = {}
        if self.friction_velocity_ is not None:
            measured = values[:, positions[self.friction_column]]
            velocity = measured
            if self.velocity_filter_ is not None:
                velocity = in_filter_order(
                    self._filter_in_filter_order, X, groups, rows={"velocity": measured}
                )
            derived.update(friction_inputs(velocity, self.friction_velocity_))
            if self.slow_velocity_filter_ is not None:
                slow = in_filter_order(
                    self._slow_in_filter_order, X, groups, rows={"velocity": measured}
                )
                derived.update(friction_inputs(slow, self.friction_velocity_, SLOW_FRICTION_NAME))
        if self.friction_angle_ is not None:
            angle = values[:, positions[self.angle_column]]
            if self.angle_lead_ is not None:
                angle = led_angle(
                    angle, values[:, positions[self.friction_column]], self.angle_lead_
                )
            plays = in_filter_order(self._play_in_filter_order, X, groups, rows={"angle": angle})
            derived.update(zip(hysteresis_names(self.friction_angle_), plays.T, strict=True))
        derived.update(load_inputs(values, positions, self.load_columns, self.powers))
        if frame is None:
            return np.column_stack([values, *derived.values()])
        out = pd.DataFrame(derived, index=frame.index)
        out = pd.concat([frame, out], axis=1)
        units = derived_units(
            frame.attrs.get("units"),
            self.friction_velocity_,
            self.load_columns,
            self.powers,
            self.friction_angle_,
            self.slow_velocity_filter_,
        )
        out.attrs = {**frame.attrs, "units": units}
        if units is None:
            del out.attrs["units"]
        return out

    def _filter_in_filter_order(self, layout, X, velocity):
        """The velocity of rows in filter order through the fitted velocity filter."""
        return filtered_velocity(velocity, layout, self.sampling_period_, self.velocity_filter_)

    def _slow_in_filter_order(self, layout, X, velocity):
        """The velocity of rows in filter order through the fitted slow velocity filter."""
        period, time_constant = self.sampling_period_, self.slow_velocity_filter_
        return filtered_velocity(velocity, layout, period, time_constant)

    def _play_in_filter_order(self, layout, X, angle):
        """The hysteresis inputs of rows in filter order, one column per play."""
        plays = recording_hysteresis(angle, layout, self.friction_angle_)
        return np.column_stack(list(plays.values()))

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
            row, ``None`` without a friction input), ``friction_velocity`` (the band, or the
            list of a basis' widths, one friction input each); ``filter_decay``,
            the velocity filter's factor per row ``exp(-sampling_period / velocity_filter)``
            (``None`` without the filter), and ``sampling_period`` (``sampling_period_``);
            ``angle_position`` (the angle's position in the row, ``None`` without hysteresis
            inputs) and ``friction_angle`` (the list of the plays' half-widths);
            ``angle_lead`` and ``lead_position`` (the velocity's position; ``None``
            without a lead): the plays read ``angle + angle_lead * velocity``;
            ``slow_filter_decay``, the slow velocity filter's factor per row (``None``
            without it: no friction inputs of a slow velocity);
            ``load_positions`` (the load columns' positions) and ``powers``.

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
        return stream_description(self)

    def _derived_names(self):
        """The derived inputs' names; before an ``"auto"`` choice, every name it may give."""
        friction, radii = self.friction_velocity_, self.friction_angle_
        if isinstance(friction, str):  # "auto": a basis of widths of the grid
            friction = WIDTH_GRID
        if isinstance(radii, str):
            radii = RADIUS_GRID
        slow = self.slow_velocity_filter_
        return derived_names(friction, self.load_columns, self.powers, radii, slow)

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        tags.input_tags.allow_nan = True
        tags.requires_fit = True
        return tags


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
    for name in LEARNED:
        if isinstance(params.get(name), str) and params[name] == AUTO:
            raise ValueError(
                f"{name}='auto' is a setting to fit; a fitted step holds the chosen value."
            )
    for name in ("velocity_filter", "slow_velocity_filter"):
        if getattr(step, name) is not None and step.sampling_period is None:
            raise ValueError(
                f"{name}={getattr(step, name)!r} needs sampling_period (the seconds between "
                "two rows); got sampling_period=None."
            )
    step.friction_velocity_ = fitted_friction(step.friction_velocity)
    step.friction_angle_ = fitted_radii(step.friction_angle)
    step.angle_lead_ = fitted_lead(step.angle_lead, step.friction_angle_)
    step.slow_velocity_filter_ = fitted_slow(step.slow_velocity_filter, step.friction_velocity)
    step.velocity_filter_ = None if step.friction_velocity is None else step.velocity_filter
    step.sampling_period_ = step.sampling_period
    step.friction_search_ = None
    step.n_features_in_ = n_features_in
    if feature_names_in is not None:
        step.feature_names_in_ = np.asarray(feature_names_in, dtype=object)
    step._check_inputs()
    return step
