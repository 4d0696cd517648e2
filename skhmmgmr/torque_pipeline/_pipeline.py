"""``TorquePipeline``: the scikit-learn ``Pipeline`` of the torque model, whose recordings
reach every step, and ``make_torque_pipeline``, the steering features in front of the
regressor.

The recordings are read once per call (``in_filter_order``: the rows put in filter order,
the results given back in the caller's order) and handed down to the steps as ``groups``.
Which step gets them is scikit-learn's metadata routing: with routing on, ``fit``,
``predict`` and ``score`` are ``Pipeline``'s own; with routing off, and for the regressor's
own methods, the steps run here, routed by the same requests (see ``_through_steps``).
"""

from functools import partial

import numpy as np
from sklearn.pipeline import Pipeline
from sklearn.utils.metadata_routing import get_routing_for_object, process_routing
from sklearn.utils.metaestimators import available_if
from sklearn.utils.validation import check_is_fitted

from .._core._compat import _routing_enabled
from .._core._docstrings import fill_shared_parameters
from .._core._panel import has_recording_index, in_filter_order
from .._core._pickled import PickleVersionMixin
from ..estimator import HMMGMRRegressor
from ..streaming import FilterStream
from ._friction_search import AUTO
from ._steering_features import SteeringFeatures

#: The methods scikit-learn's ``Pipeline`` routes metadata to, of those the steps run here.
ROUTED_METHODS = ("predict", "score")
#: Parameters of the regressor's ``predict`` that are its own, not metadata.
OWN_PREDICT_PARAMETERS = frozenset({"return_std", "time"})


def _final_step_has(method):
    """``available_if`` check: the pipeline's last step has ``method``."""

    def check(pipeline):
        return hasattr(pipeline.steps[-1][1], method)

    return check


def _n_rows(X):
    return X.shape[0] if hasattr(X, "shape") else len(X)


def _consumes_groups(step, *methods):
    """Whether ``step`` requests ``groups`` in one of ``methods`` by its own defaults (the
    package's steps do). With metadata routing off nobody can set a request, so a step that
    leaves it unset (any step of another library with a ``groups`` parameter) gets none, as
    from scikit-learn's ``Pipeline``, instead of an error asking for ``set_fit_request``,
    which routing off refuses."""
    routing = get_routing_for_object(step)
    return any(routing.consumes(method, ["groups"]) for method in methods)


def _reads_layouts(step):
    """Whether the step reads a :class:`~skhmmgmr._core._panel.RecordingLayout` as its
    ``groups`` (the package's steps do; another library's step gets the recording ids)."""
    return isinstance(step, SteeringFeatures | HMMGMRRegressor)


def _needs_recordings(step):
    """Whether the step's output depends on where recordings begin (a filter or plays over
    the rows, or a choice of them)."""
    if not isinstance(step, SteeringFeatures):
        return False
    if step.friction_angle is not None:
        return True
    if step.velocity_filter is None:
        return False
    return step.velocity_filter != AUTO or step.sampling_period is not None


class TorquePipeline(PickleVersionMixin, Pipeline):
    """The :class:`~sklearn.pipeline.Pipeline` of :func:`make_torque_pipeline`: recordings
    given once reach every step that reads them.

    ``fit``, ``predict`` and ``score`` take ``groups`` (the recording id of every row), read
    the recordings once, and hand them to every step that requests them (scikit-learn's
    metadata routing: the package's steps request ``groups`` by default), with routing on or
    off; with routing off, a scikit-learn ``Pipeline`` passes ``groups`` only to the steps
    named in ``<step>__groups`` at fit and to no transformer at predict, so a velocity filter
    would run across recordings. A
    ``<step>__groups`` that leaves out a step whose output depends on the recordings is
    refused, naming the step. Recordings in the
    index of a panel (:func:`skhmmgmr.datasets.to_panel`) reach every step as they are.
    A step of another library gets ``groups`` when it requests them (routing on) as an array
    of recording ids, the rows in the order the fit reads them (recordings in the order of
    their ids); with routing off, where no request can be set, it gets none, as from a
    scikit-learn ``Pipeline``.

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
        """Fit every step, ``groups`` handed to every step that requests it.

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
        if params:  # per-row fit parameters would need the rows' order too: fitted as given
            return super().fit(X, y, **self._fit_params(X, groups, params))
        return in_filter_order(self._fit_in_filter_order, X, groups, y=y, canonical=True)

    def _fit_in_filter_order(self, layout, X, y=None):
        return super().fit(X, y, **self._fit_params(X, self._groups_for_steps(layout), {}))

    def _groups_for_steps(self, layout):
        """What the steps get as ``groups``: the handed-down layout, or the recording ids of
        the rows (a plain array: ``pandas.unique``, ``groupby``...) when a step of another
        library requests them."""
        handed = layout.handed_down()
        methods = ("fit", "fit_transform", "transform", *ROUTED_METHODS)
        foreign = [
            step
            for _, step in self.steps
            if not _reads_layouts(step) and _consumes_groups(step, *methods)
        ]
        return handed if handed is None or not foreign else np.asarray(handed)

    def _fit_params(self, X, groups, params):
        """``params`` with ``groups`` for every step that requests it, as scikit-learn's
        ``Pipeline.fit`` takes them: the metadata itself with routing on; with routing off,
        ``<step>__groups`` for each step that scikit-learn's routing names (``Pipeline``
        would otherwise give them to none)."""
        if groups is not None:
            if _routing_enabled():
                return {**params, "groups": groups}
            for name, step in self.steps:
                if _consumes_groups(step, "fit", "fit_transform"):
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
                "output depends on where each recording begins (a filter or plays over the "
                "rows): pass "
                f"groups= to the pipeline itself, which hands them to every step, or give X the "
                "recordings in its index (skhmmgmr.datasets.to_panel)."
            )
        return params

    def predict(self, X, groups=None, **params):
        """The final step's prediction, ``groups`` handed to every step that requests it.

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
        time = params.pop("time", None)
        return self._final_method("predict", X, groups, per_row={"time": time}, **params)

    def _final_method(self, method, X, groups, *args, y=None, per_row=None, **params):
        """The final step's ``method`` on ``X`` through the transformers, the recordings read
        once and handed to every step that takes them, ``y`` (paired by label with a panel)
        and the arrays of ``per_row`` in filter order; results in the caller's row order."""
        check_is_fitted(self)
        run = partial(self._final_in_filter_order, method, args, params)
        return in_filter_order(run, X, groups, y=y, rows=per_row)

    def _final_in_filter_order(self, method, args, params, layout, X, **rows):
        """:meth:`_final_method` on rows in filter order, their recordings' ``layout`` read."""
        groups = self._groups_for_steps(layout)
        params = {**params, **{name: value for name, value in rows.items() if value is not None}}
        routed = method in ROUTED_METHODS and not OWN_PREDICT_PARAMETERS & params.keys()
        if routed and _routing_enabled():
            extra = {} if groups is None else {"groups": groups}
            return getattr(super(), method)(X, *args, **extra, **params)
        return self._through_steps(method, X, groups, args, params)

    def _through_steps(self, method, X, groups, args, params):
        """The final step's ``method`` on ``X`` through the transformers, run here.

        scikit-learn's ``Pipeline`` passes no metadata to a transformer with routing off, and
        the regressor's own methods (``predict`` with ``return_std`` or ``time``,
        ``predict_state_proba``, ``predict_ahead``, ``adapt``) are no ``Pipeline`` methods;
        which step gets ``groups`` is still scikit-learn's routing (the requests of the
        steps, as ``predict`` routes them), and the final step's own method takes them as
        its own parameter."""
        routing = self._routing_of(method if method in ROUTED_METHODS else "predict", groups)
        Xt = X
        for name, step in self.steps[:-1]:
            if step is not None and step != "passthrough":
                Xt = step.transform(Xt, **routing(name, step, "transform"))
        name, final = self.steps[-1]
        if method in ROUTED_METHODS:
            params = {**routing(name, final, method), **params}
        elif groups is not None:
            params = {**params, "groups": groups}
        return getattr(final, method)(Xt, *args, **params)

    def _routing_of(self, caller, groups):
        """``routing(name, step, method)``: the metadata that ``method`` of the step gets in
        the pipeline's ``caller``: scikit-learn's routing with routing on; with routing off,
        ``groups`` for a step that requests them by default (:func:`_consumes_groups`)."""
        if groups is None:
            return lambda name, step, method: {}
        if _routing_enabled():
            routed = process_routing(self, caller, groups=groups)
            return lambda name, step, method: routed[name][method]
        return lambda name, step, method: (
            {"groups": groups} if _consumes_groups(step, method) else {}
        )

    @available_if(_final_step_has("predict_state_proba"))
    def predict_state_proba(self, X, groups=None, time=None):
        """The regressor's filtered state probabilities given the inputs up to each row.

        ``X`` goes through the transformers first, ``groups`` handed to every step that
        requests it (with metadata routing on or off), as in :meth:`predict`.

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
        return self._final_method("predict_state_proba", X, groups, per_row={"time": time})

    @available_if(_final_step_has("predict_ahead"))
    def predict_ahead(
        self, X, steps, groups=None, time=None, *, state_output="marginal", return_std=False
    ):
        """The regressor's forecast of the outputs ``steps`` rows ahead.

        ``X`` goes through the transformers first, ``groups`` handed to every step that
        requests it (with metadata routing on or off), as in :meth:`predict`.

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
            per_row={"time": time},
            state_output=state_output,
            return_std=return_std,
        )

    @available_if(_final_step_has("adapt"))
    def adapt(
        self, X, y, groups=None, *, relevance="auto", parameters="auto", n_iter=10, time=None
    ):
        """Adapt the fitted regressor to new recordings (MAP EM); the transformers stay.

        ``X`` goes through the transformers first, ``groups`` handed to every step that
        requests it (with metadata routing on or off), then the regressor adapts as
        :meth:`HMMGMRRegressor.adapt <skhmmgmr.HMMGMRRegressor.adapt>` does, in place: by
        default the new recordings choose how far it moves, from not at all to a fresh fit
        of the regressor on their derived rows (the table of the choice in
        ``pipeline[-1].adaptation_``).

        Parameters
        ----------
        X : DataFrame or array-like of shape (n_samples, n_features)
            Inputs of the new recordings.
        y : array-like of shape (n_samples,) or (n_samples, n_outputs)
        groups : array-like of shape (n_samples,), default=None
            Recording id of every row.
        relevance : float or "auto", default="auto"
            Relevance factor ``r``: rows of evidence at which a state moves halfway; ``inf``
            does not adapt, ``0`` fits the regressor anew. "auto": chosen from the new
            recordings.
        parameters : str or "auto", default="auto"
            Which parameters adapt: any of "m" (means), "v" (covariances), "t" (transitions).
            "auto": chosen with the relevance.
        n_iter : int, default=10
            Maximum number of MAP EM iterations.
        time : array-like of shape (n_samples,), default=None
            Optional time stamps, checked to increase within every recording.

        Returns
        -------
        self : TorquePipeline
            With the regressor adapted (a new ``model_``, the previous one not modified; no
            rows, or the choice not to adapt, leave it unchanged).

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
        >>> int(pipe.adapt(X[:400], y[:400] + 0.2)[-1].adaptation_["chosen"].sum())  # "auto"
        1
        """
        options = {"relevance": relevance, "parameters": parameters, "n_iter": n_iter}
        if _n_rows(X) == 0:  # nothing to derive: the regressor checks y and groups, keeps its model
            check_is_fitted(self)
            self.steps[-1][1].adapt(X, y, groups=groups, time=time, **options)
            return self
        self._final_method("adapt", X, groups, y=y, per_row={"time": time}, **options)
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
        """The final step's score, ``groups`` handed to every step that requests it.

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
        per_row = {"sample_weight": sample_weight}
        return self._final_method("score", X, groups, y=y, per_row=per_row, **params)


def check_regressor_params(params, caller, own):
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
    friction_angle="auto",
    angle_lead="auto",
    slow_velocity_filter="auto",
    **params,
):
    """HMM-GMR behind the steering system's derived inputs: a scikit-learn ``Pipeline``.

    The pipeline is ``SteeringFeatures`` (step ``"steering_features"``) then
    :class:`~skhmmgmr.HMMGMRRegressor` (step ``"hmmgmr"``). It takes data frames with the
    package's column names (:data:`skhmmgmr.datasets.FEATURE_NAMES`); recordings reach both
    steps in the index of a panel (:func:`skhmmgmr.datasets.to_panel`), or as ``groups=`` given
    to the pipeline's ``fit``, ``predict`` and ``score`` (:class:`TorquePipeline`), with
    metadata routing on or off. ``hmmgmr__groups=`` alone is refused with ``velocity_filter``
    or ``friction_angle``: the filter or the plays of ``SteeringFeatures`` would run across
    recordings. On the simulator's
    protocol it is more accurate than a default gradient-boosting regressor and
    smoother (see "When to use HMM-GMR" in the user guide, and
    ``benchmarks/bench_baselines.py``).

    Parameters
    ----------
    n_states : int, default=5
        Number of hidden states of the regressor; choose it on validation recordings
        (:class:`~skhmmgmr.StateSelector`, or a ``GridSearchCV`` over ``hmmgmr__n_states``).
    friction_velocity, load_columns, powers, velocity_filter, friction_angle, angle_lead, \
slow_velocity_filter
        Passed to :class:`SteeringFeatures`. By default (``"auto"``) the friction inputs (a
        basis of one or several widths, from the narrowest the velocity resolves to the widest
        the data needs, or none), the hysteresis inputs (plays on the steering-wheel angle, or
        none), the velocity filter and the slow velocity filter (friction inputs of the
        velocity low-passed over 0.1 or 0.2 s as well, or none) are chosen in ``fit`` on the
        training recordings
        (``pipeline[0].friction_search_``), so that they suit the car; a number fixes one
        band, a tuple of widths a basis; ``friction_angle=None`` leaves out the hysteresis
        inputs, whose plays restart at every recording. The filter is
        considered only with a sampling period (at 100 Hz it keeps the velocity sensor's
        noise out of the friction input). The recordings reach the transformer through
        ``groups`` given to the pipeline or a panel index.
    {sampling_period}
        Passed to :class:`SteeringFeatures`, for the velocity filter. ``None``: read in
        ``fit`` from the ``time`` level of a panel's index
        (:func:`skhmmgmr.datasets.to_panel`), the median step within its recordings, as the
        command line reads it (``pipeline[0].sampling_period_``).
    output_smoothing : None, float >= 0 or "auto", default="auto"
        Passed to :class:`~skhmmgmr.HMMGMRRegressor`: the causal first-order read-out of
        the estimate. By default the weakest whose estimate of the training recordings is no
        rougher than the measured torque there (``pipeline[-1].output_smoothing_``, in rows;
        0 when the estimate already is not, or when that read-out changes nothing that
        matters: the roughness by less than 1 % and no recording's accuracy by 0.1 point);
        None: the filter's estimate itself.
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
    check_regressor_params(
        params,
        "make_torque_pipeline",
        "n_states, friction_velocity, load_columns, powers, velocity_filter, sampling_period, "
        "output_smoothing, friction_angle, angle_lead, slow_velocity_filter",
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
                    friction_angle=friction_angle,
                    angle_lead=angle_lead,
                    slow_velocity_filter=slow_velocity_filter,
                ),
            ),
            (
                "hmmgmr",
                HMMGMRRegressor(n_states=n_states, output_smoothing=output_smoothing, **params),
            ),
        ]
    )
