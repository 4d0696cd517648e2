"""The package's only door to scikit-learn's private API.

scikit-learn may rename, move or drop anything private (a ``_``-prefixed module or name) in any
release without a deprecation cycle. Every such name the package needs is imported here, and
only here (``tests/test_compat.py`` checks it), so that a change in a new scikit-learn release,
or a difference in the oldest supported one, is dealt with in this one module, with a version
switch if a name moves. imbalanced-learn keeps the same kind of shim
(``imblearn/utils/_sklearn_compat.py``).

Per name: what it is and the first scikit-learn release that has it at this import path. All
of them predate the oldest supported release (``scikit-learn>=1.8`` in ``pyproject.toml``) and
sit at the same path from 1.8 to 1.9, so no version switch is needed yet.
"""

import math

import numpy as np
from sklearn.base import (
    _fit_context,  # fit decorator: validates _parameter_constraints once; since 1.3
)
from sklearn.utils._param_validation import (
    HasMethods,  # constraint: an object having the given methods; since 1.2
    InvalidParameterError,  # what the constraints raise (a ValueError and a TypeError); 1.2
    StrOptions,  # constraint: one of a set of strings; since 1.2
    validate_parameter_constraints,  # check a dict of parameters against constraints; 1.2
    validate_params,  # decorator: a public function's arguments against constraints; 1.2
)
from sklearn.utils._param_validation import (
    Interval as _SklearnInterval,  # constraint: a number in a range (bools too); since 1.2
)
from sklearn.utils.metadata_routing import (
    _MetadataRequester,  # base class giving set_{method}_request and defaults; since 1.3
    _routing_enabled,  # whether enable_metadata_routing is on in the config; since 1.3
)


class Interval(_SklearnInterval):
    """scikit-learn's ``Interval`` constraint, refusing bools.

    ``True`` is an ``Integral`` and a ``Real`` in Python, so scikit-learn's constraint takes
    ``n_states=True`` for 1 and ``sampling_period=True`` for 1 s; a bool in a numeric
    parameter is a mistake, and the error names the parameter.
    """

    def is_satisfied_by(self, val):
        return not isinstance(val, bool | np.bool_) and super().is_satisfied_by(val)

    def __str__(self):
        return f"{super().__str__()} (not a bool)"


class FiniteInterval(Interval):
    """:class:`Interval` refusing infinite values (and NaN, which no interval holds).

    An unbounded side (``None``) of scikit-learn's ``Interval`` takes ``inf``; a duration, a
    rate, a speed or a time constant of ``inf`` is a mistake that would otherwise surface as an
    ``OverflowError`` or a memory error long after the call.
    """

    def is_satisfied_by(self, val):
        if not super().is_satisfied_by(val):
            return False
        try:
            return math.isfinite(val)
        except OverflowError:  # an int beyond the largest float
            return False

    def __str__(self):
        return f"{super().__str__()} and finite"


__all__ = [
    "FiniteInterval",
    "HasMethods",
    "Interval",
    "InvalidParameterError",
    "StrOptions",
    "_MetadataRequester",
    "_fit_context",
    "_routing_enabled",
    "validate_parameter_constraints",
    "validate_params",
]
