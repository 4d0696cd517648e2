"""Where downloaded datasets are cached."""

import os
import shutil
from pathlib import Path

from .._core._compat import validate_params

DATA_HOME_ENV = "SKHMMGMR_DATA"
#: What ``data_home`` may be, for every function that takes it.
DATA_HOME = [str, os.PathLike, None]


@validate_params({"data_home": DATA_HOME}, prefer_skip_nested_validation=True)
def get_data_home(data_home=None):
    """Return the folder where skhmmgmr caches downloaded datasets, creating it if needed.

    The folder is, in order of precedence, ``data_home`` when given, the value of the
    environment variable ``SKHMMGMR_DATA`` when set and not empty, else ``~/skhmmgmr_data``.
    A leading ``~`` is expanded.

    Parameters
    ----------
    data_home : str or path-like, default=None
        The folder to use instead of the default one.

    Returns
    -------
    data_home : str
        Path of the cache folder.

    Examples
    --------
    >>> import os, tempfile
    >>> from skhmmgmr.datasets import clear_data_home, get_data_home
    >>> home = os.path.join(tempfile.mkdtemp(), "skhmmgmr_cache")
    >>> get_data_home(home) == home
    True
    >>> clear_data_home(home)
    """
    if data_home is None:
        data_home = os.environ.get(DATA_HOME_ENV) or os.path.join("~", "skhmmgmr_data")
    data_home = Path(os.fspath(data_home)).expanduser()
    data_home.mkdir(parents=True, exist_ok=True)
    return str(data_home)


@validate_params({"data_home": DATA_HOME}, prefer_skip_nested_validation=True)
def clear_data_home(data_home=None):
    """Delete the cache folder and everything in it.

    Parameters
    ----------
    data_home : str or path-like, default=None
        The folder to delete; by default the one :func:`get_data_home` returns.

    Examples
    --------
    >>> import os, tempfile
    >>> from skhmmgmr.datasets import clear_data_home, get_data_home
    >>> home = get_data_home(os.path.join(tempfile.mkdtemp(), "skhmmgmr_cache"))
    >>> clear_data_home(home)
    >>> os.path.exists(home)
    False
    """
    shutil.rmtree(get_data_home(data_home))
