"""Deprecated aliases: a public function or method kept for one release, warning what to call.

A name that leaves the public API stays one release as a thin alias of what replaces it: the
call still works, and warns with a ``FutureWarning`` (shown to users by default, as
scikit-learn's deprecations are) that names the release that removes it and what to call
instead. Its docstring says the same in a ``.. deprecated::`` note.
"""

import functools
import warnings

#: The release that deprecates and the one that removes the aliases of this release.
DEPRECATED_IN, REMOVED_IN = "0.2", "0.3"


def deprecated_alias(name, instead):
    """Decorate a function (or the function of a method) kept for one release.

    Parameters
    ----------
    name : str
        How users call it (``"HMMGMRRegressor.to_dict"``).
    instead : str
        What to call instead, as a sentence after a semicolon.
    """
    message = (
        f"{name} is deprecated since skhmmgmr {DEPRECATED_IN} and will be removed in "
        f"{REMOVED_IN}; {instead}"
    )

    def decorate(function):
        @functools.wraps(function)
        def alias(*args, **kwargs):
            warnings.warn(message, FutureWarning, stacklevel=2)
            return function(*args, **kwargs)

        return alias

    return decorate
