"""``write_c``: the causal filter of a fitted model as C99 source, ``<name>.h`` and ``<name>.c``.

The model is read into flat arrays (:func:`~skhmmgmr.export._model.read_filter`), the header
and the source written from them (:mod:`._c_header`, :mod:`._c_source`), then both files
through the package's one rule for output files (:mod:`skhmmgmr._core._files`): checked before
anything is written (a missing folder is created, an existing file is replaced only with
``overwrite=True``), each written to an exclusively created temporary file renamed into place.
"""

import os
from pathlib import Path

from .._core._compat import validate_params
from .._core._files import check_output_paths, write_atomically
from ._c_header import header
from ._c_source import source
from ._model import check_dtype, check_name, read_filter


@validate_params(
    {
        "fitted": "no_validation",  # refused by read_filter, saying why
        "directory": [str, os.PathLike],
        "name": [str],
        "dtype": "no_validation",  # a name or a NumPy type, read by check_dtype
        "overwrite": ["boolean"],
    },
    prefer_skip_nested_validation=True,
)
def write_c(fitted, directory, *, name="skhmmgmr_model", dtype="float64", overwrite=False):
    """Write the causal filter of a fitted model as C99 source: ``<name>.h`` and ``<name>.c``.

    The generated filter gives, sample by sample, the estimates of ``predict`` and of
    :class:`~skhmmgmr.FilterStream`: the same normalised forward recursion in log space,
    restart rule, predictive standard deviation and outlier policy (the regressor's
    ``min_log_density``: by default no sample is held for its distance to the states). It
    needs only the C standard library and ``math.h``, allocates nothing, and builds with
    ``cc -std=c99 -O2 -Wall -Wextra -Werror -pedantic`` (``dtype="float32"`` also with
    ``-Wdouble-promotion``). Its C API, ``real`` being ``double`` or ``float``
    (``<name>_real``)::

        int         <name>_n_inputs(void);     /* raw inputs, in the fitted input order */
        int         <name>_n_outputs(void);
        const char *<name>_input_name(int i);
        size_t      <name>_state_size(void);   /* bytes of one filter state */
        void        <name>_reset(<name>_state *state);   /* start of a recording */
        int         <name>_update(<name>_state *state, const real *inputs,
                                  real *estimate, real *std);

    ``<name>_update`` returns 0 when the sample was filtered, 1 when an input is not finite
    and 2 when it is out of the model's range or below ``min_log_density`` (the two held
    cases of :class:`~skhmmgmr.FilterStream`: the estimate is the last one and the state is
    unchanged); ``std`` may be ``NULL``.

    Parameters
    ----------
    fitted : HMMGMRRegressor or Pipeline
        A fitted regressor, or a fitted pipeline of :class:`~skhmmgmr.SteeringFeatures`
        then the regressor (:func:`~skhmmgmr.make_torque_pipeline`): the C code then takes
        the raw inputs and computes the derived ones itself, velocity filter included
        (reset with the recording).
    directory : str or path-like
        The folder of the two files, created when missing.
    name : str, default="skhmmgmr_model"
        C identifier prefixing the files, the functions and the state type; not the name of
        a C standard header (``math``, ``stddef``..., in any case), which the generated file
        would hide.
    dtype : {"float64", "float32"}, default="float64"
        Arithmetic of the filter: "float32" runs everything in single precision, the
        derived inputs, the read-out and the API's inputs and estimates included (``float``
        literals, ``expf``, ``tanhf``, ``powf``), for microcontrollers whose floating-point
        unit is single precision: no double-precision operation is left.
    overwrite : bool, default=False
        Whether existing files are replaced; without it they are refused before anything
        is written.

    Returns
    -------
    paths : tuple of Path
        The header and the source written.

    Raises
    ------
    ValueError
        For a model fitted with ``missing_values`` other than "error" (the C filter holds a
        sample with a NaN input instead of marginalising it), a pipeline with other steps,
        a ``name`` that is not a C identifier or names a standard header, an unknown
        ``dtype``, a parameter that single precision cannot hold (``dtype="float32"``).
    FileExistsError
        For an existing file and ``overwrite=False``.
    sklearn.exceptions.NotFittedError
        For an unfitted model.

    Notes
    -----
    Online adaptation (:class:`~skhmmgmr.FilterStream` with ``relevance``) is not
    generated: export the adapted model instead, ``HMMGMRRegressor.from_fitted_model(
    stream.adapted_model())``. See the user guide, "C code of a fitted model".

    Examples
    --------
    >>> import tempfile
    >>> import numpy as np
    >>> from skhmmgmr import HMMGMRRegressor
    >>> from skhmmgmr.export import write_c
    >>> X = np.cumsum(np.random.default_rng(0).normal(size=(300, 2)), axis=0) / 10
    >>> model = HMMGMRRegressor(n_states=2, random_state=0).fit(X, X.sum(axis=1))
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     paths = write_c(model, folder, name="steering")
    ...     [path.name for path in paths]
    ['steering.h', 'steering.c']
    """
    name, dtype = check_name(name), check_dtype(dtype)
    directory = Path(directory)
    paths = (directory / f"{name}.h", directory / f"{name}.c")
    check_output_paths(paths, overwrite=overwrite, option="directory")
    spec = read_filter(fitted)
    texts = (header(spec, name, dtype), source(spec, name, dtype))
    for path, text in zip(paths, texts, strict=True):
        write_atomically(path, text)
    return paths
