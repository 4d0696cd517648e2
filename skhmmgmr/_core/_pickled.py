"""The package version every pickle of the package's objects carries, checked on loading.

A pickle (or a joblib or skops file) holds an object's attributes, not its code: loaded by
another release of skhmmgmr, whose classes may hold other attributes or compute otherwise, it
may fail or, worse, predict differently without a word. As scikit-learn does for its own
estimators (``_sklearn_version``), :class:`PickleVersionMixin` adds the version of skhmmgmr
that wrote the object to its pickled state and warns with
:class:`InconsistentVersionWarning` when another version loads it. The model file of
:mod:`skhmmgmr.portable` is the format meant to last across releases.
"""

import warnings

from .._version import __version__

# The key of the version in a pickled state; a state without it was written before pickles
# carried the version (skhmmgmr 0.1.0).
VERSION_KEY = "_skhmmgmr_version"
UNRECORDED = "0.1.0 or earlier (no version recorded)"


class InconsistentVersionWarning(UserWarning):
    """Warns that an object was pickled by another version of skhmmgmr than the one loading it.

    Loading a pickle, joblib or skops file across versions may fail or give other results:
    save models meant to last with :func:`skhmmgmr.portable.save`, a plain JSON file that
    later versions read and predict from bit for bit.

    Parameters
    ----------
    class_name : str
        The class of the object loaded.
    original_version : str
        The skhmmgmr version that pickled it.
    current_version : str
        The skhmmgmr version loading it.

    Attributes
    ----------
    class_name, original_version, current_version : str
        As given.

    Examples
    --------
    A pickle loaded by the version that wrote it loads without a word:

    >>> import pickle, warnings
    >>> from skhmmgmr import HMMGMRRegressor, InconsistentVersionWarning
    >>> with warnings.catch_warnings():
    ...     warnings.simplefilter("error", InconsistentVersionWarning)
    ...     restored = pickle.loads(pickle.dumps(HMMGMRRegressor(n_states=3)))
    >>> restored.n_states
    3
    """

    def __init__(self, class_name, original_version, current_version):
        super().__init__(class_name, original_version, current_version)
        self.class_name = class_name
        self.original_version = original_version
        self.current_version = current_version

    def __str__(self):
        return (
            f"Loading a pickled {self.class_name} written by skhmmgmr {self.original_version} "
            f"with skhmmgmr {self.current_version}: it may fail or predict differently. Keep "
            "models across versions in the model file of skhmmgmr.portable.save, which later "
            "versions read bit for bit."
        )


class PickleVersionMixin:
    """Adds the version of skhmmgmr to an object's pickled state and checks it on loading.

    Put it first among the bases of a class whose objects users pickle (the estimators, the
    fitted model, the stream, the scorers, the selection report). A class that defines its
    own ``__setstate__`` calls ``super().__setstate__(state)`` in it.
    """

    def __getstate__(self):
        parent = getattr(super(), "__getstate__", None)
        state = parent() if parent is not None else None
        state = dict(self.__dict__ if state is None else state)
        state[VERSION_KEY] = __version__
        return state

    def __setstate__(self, state):
        written = state.pop(VERSION_KEY, UNRECORDED)
        if written != __version__:
            warnings.warn(
                InconsistentVersionWarning(type(self).__name__, written, __version__),
                stacklevel=2,
            )
        parent = getattr(super(), "__setstate__", None)
        if parent is not None:
            parent(state)
        else:
            self.__dict__.update(state)
