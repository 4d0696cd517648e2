"""``write_fmu``: a fitted model as a co-simulation Functional Mock-up Unit (FMI 2.0 or 3.0).

The FMU is a zip archive:

- ``modelDescription.xml`` (:mod:`._fmu_description`): the raw inputs, the estimate, std and
  status outputs, the units, the sampling period as the default and only communication step;
- ``sources/``: the filter that :func:`~skhmmgmr.export.write_c` generates (``<name>.h``,
  ``<name>.c``) and its FMI wrapper (:mod:`._fmu_wrapper`), and for FMI 3.0
  ``buildDescription.xml``, so that an importer on another platform builds the binary;
- ``binaries/<platform>/<name>.<so|dylib|dll>``: the sources compiled for this platform with
  the system C compiler ``cc`` against the FMI headers that FMPy ships (they come from the
  installed FMPy at build time and are not put in the FMU, as the standard asks).

The archive is written at once through :func:`~skhmmgmr._core._files.write_atomically`; its
entries carry a fixed date, and the instantiation token is a hash of what the FMU computes, so
that the same model exported twice gives the same token.
"""

import hashlib
import importlib.util
import io
import math
import os
import shutil
import subprocess
import tempfile
import uuid
import zipfile
from collections.abc import Mapping
from dataclasses import replace
from numbers import Real
from pathlib import Path

from sklearn.pipeline import Pipeline

from .._core._compat import FiniteInterval, StrOptions, validate_params
from .._core._files import check_output_paths, write_atomically
from .._core._schema import TARGET
from ._c import write_c
from ._fmu_description import build_description, describe, model_description
from ._fmu_wrapper import wrapper, wrapper_name
from ._model import check_name, read_filter

FMI_VERSIONS = ("2.0", "3.0")
_FLAGS = ("-std=c99", "-O2", "-fPIC", "-shared", "-fvisibility=hidden")
_ENTRY_DATE = (1980, 1, 1, 0, 0, 0)
_INSTALL_FMPY = "pip install 'skhmmgmr[fmu]'"


def _model_identifier(name, path):
    """``name``, or the file's stem made a C identifier (other characters as ``_``; a stem
    that does not start with a letter gets the prefix ``fmu_``)."""
    if name is None:
        stem = "".join(c if c.isascii() and (c.isalnum() or c == "_") else "_" for c in path.stem)
        name = stem if stem[:1].isalpha() else f"fmu_{stem}"
    return check_name(name)


def _model_period(fitted):
    """The sampling period a pipeline's steps use (the first one set: given, or read from the
    training rows' time, ``sampling_period_``), or None."""
    steps = fitted.steps if isinstance(fitted, Pipeline) else []
    periods = [
        getattr(step, "sampling_period_", getattr(step, "sampling_period", None))
        for _, step in steps
    ]
    return next((float(p) for p in periods if p is not None), None)


def _sampling_period(fitted, sampling_period):
    own = _model_period(fitted)
    if sampling_period is None:
        if own is None:
            raise ValueError(
                "write_fmu needs the model's sampling period, the seconds between two samples "
                "of the recordings it was fitted on (the FMU's only communication step): pass "
                "sampling_period=, or give the pipeline's SteeringFeatures a sampling_period."
            )
        return own
    if own is not None and not math.isclose(own, sampling_period, rel_tol=1e-12):
        raise ValueError(
            f"sampling_period={sampling_period!r} is not the period the model's "
            f"SteeringFeatures were fitted with ({own!r} s), on which its velocity filter "
            "depends: leave sampling_period=None."
        )
    return float(sampling_period)


def _output_names(output_names, n_outputs):
    if output_names is None:
        return (TARGET,) if n_outputs == 1 else tuple(f"output_{i}" for i in range(n_outputs))
    names = (output_names,) if isinstance(output_names, str) else tuple(output_names)
    if len(names) != n_outputs or not all(isinstance(n, str) and n for n in names):
        raise ValueError(
            f"output_names must be {n_outputs} non-empty name(s), one per output of the model; "
            f"got {output_names!r}."
        )
    return names


def fmi_headers():
    """The folder of the FMI headers that the installed FMPy ships, or an ImportError."""
    spec = importlib.util.find_spec("fmpy")
    if spec is None or not spec.submodule_search_locations:
        raise ImportError(
            "write_fmu compiles the FMU against the FMI headers that FMPy ships, and FMPy is "
            f"not installed: {_INSTALL_FMPY} (or pass binary=False for an FMU of sources only)."
        )
    folder = Path(spec.submodule_search_locations[0]) / "c-code"
    missing = [h for h in ("fmi2Functions.h", "fmi3Functions.h") if not (folder / h).is_file()]
    if missing:
        raise ImportError(
            f"the installed FMPy ships no FMI headers {missing} in {folder}: "
            f"{_INSTALL_FMPY} installs a version that does."
        )
    return folder


def _binary_path(name, fmi_version):
    """``binaries/<platform>/<name><extension>`` of this platform, as FMPy names it."""
    import fmpy

    platform = fmpy.platform if fmi_version == "2.0" else fmpy.platform_tuple
    return f"binaries/{platform}/{name}{fmpy.sharedLibraryExtension}"


def _compile(folder, sources, target, headers):
    compiler = shutil.which("cc")
    if compiler is None:
        raise RuntimeError(
            "write_fmu compiles the FMU's binary with the system C compiler, and there is no "
            "'cc' on the PATH: install one (gcc or clang), or pass binary=False for an FMU of "
            "sources only, which the importer builds."
        )
    output = folder / target
    output.parent.mkdir(parents=True)
    command = [compiler, *_FLAGS, f"-I{headers}", f"-I{folder / 'sources'}", "-o", str(output)]
    command += [str(folder / "sources" / source) for source in sources] + ["-lm"]
    result = subprocess.run(command, capture_output=True, text=True)
    if result.returncode != 0:
        raise RuntimeError(
            f"the C compiler failed to build the FMU's binary ({' '.join(command)}):\n"
            f"{result.stderr.strip()}"
        )
    return output.read_bytes()


def _token(texts):
    digest = hashlib.sha256("\0".join(texts).encode("utf-8")).hexdigest()
    return "{" + str(uuid.uuid5(uuid.NAMESPACE_OID, digest)) + "}"


def _archive(entries):
    """The zip archive of ``{name: bytes}``, ``modelDescription.xml`` first, fixed dates."""
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED) as archive:
        for name in sorted(entries, key=lambda n: (n != "modelDescription.xml", n)):
            info = zipfile.ZipInfo(name, date_time=_ENTRY_DATE)
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = (0o755 if name.startswith("binaries/") else 0o644) << 16
            archive.writestr(info, entries[name])
    return buffer.getvalue()


@validate_params(
    {
        "fitted": "no_validation",  # refused by read_filter, saying why
        "path": [str, os.PathLike],
        "fmi_version": [StrOptions(set(FMI_VERSIONS))],
        "name": [str, None],
        "sampling_period": [FiniteInterval(Real, 0, None, closed="neither"), None],
        "output_names": [str, "array-like", None],
        "units": [Mapping, None],
        "binary": ["boolean"],
        "overwrite": ["boolean"],
    },
    prefer_skip_nested_validation=True,
)
def write_fmu(
    fitted,
    path,
    *,
    fmi_version="2.0",
    name=None,
    sampling_period=None,
    output_names=None,
    units=None,
    binary=True,
    overwrite=False,
):
    """Write a fitted model as a co-simulation Functional Mock-up Unit (a ``.fmu`` file).

    The FMU runs the causal filter that :func:`write_c` generates, one sample per
    communication step, behind the FMI 2.0 or 3.0 co-simulation interface: any importer of the
    standard (FMPy, Simulink, IPG CarMaker, dSPACE, OpenModelica, the Open Simulation
    Platform) loads it. It holds the generated C and its FMI wrapper as sources (FMI 3.0 with
    ``buildDescription.xml``) and, with ``binary``, a binary for this platform compiled with
    the system C compiler ``cc`` against the FMI headers that FMPy ships.

    Variables (value references in brackets): the raw inputs in the fitted order [1..],
    then every output's estimate, then its predictive standard deviation (``<output>_std``),
    then ``update_status`` (Integer: 0 the sample was filtered, 1 held as an input is not
    finite, 2 held as an outlier, -1 no step since the start or the last reset); FMI 3.0
    adds the independent variable ``time`` [0]. Units come from the package's schema
    (:data:`~skhmmgmr.datasets.FEATURE_UNITS`, ``Nm`` for ``driver_torque``) and ``units``.

    Stepping: ``doStep(t, h)`` takes the inputs set before it as the sample at ``t`` and
    filters it; after the step the outputs are that sample's estimate, std and status (held
    until the next step), so the outputs depend on no input of the same instant. ``h`` must be
    the sampling period (within 1e-6 of it): a step of another size is refused with an error
    status and a logged message, and changes nothing. The outputs before any step are the
    prior mixture's mean and std. ``reset`` (``fmi2Reset``/``fmi3Reset``) restarts the
    filter, as the start of a new recording; every instance has its own state.

    Parameters
    ----------
    fitted : HMMGMRRegressor, HierarchicalHMMGMRRegressor or Pipeline
        Any fitted model :func:`write_c` takes (a torque pipeline with its velocity filter
        and read-out included); the same errors for the others.
    path : str or path-like
        The ``.fmu`` file to write.
    fmi_version : {"2.0", "3.0"}, default="2.0"
        The FMI version of the FMU.
    name : str, default=None
        The model identifier: the C prefix of the generated code and the binary's name. By
        default the file's stem, every character but ASCII letters, digits and ``_`` as
        ``_`` (prefixed with ``fmu_`` unless it starts with a letter).
    sampling_period : float, default=None
        Seconds between two samples: the FMU's communication step. By default the
        ``sampling_period`` of the pipeline's :class:`~skhmmgmr.SteeringFeatures`; required
        for a model without one.
    output_names : list of str, default=None
        Names of the outputs; by default ``driver_torque`` for a model of one output,
        ``output_0``... for more.
    units : dict, default=None
        Unit texts by input or output name, completing (and overriding) the schema's.
    binary : bool, default=True
        Compile a binary for this platform (needs ``cc`` and FMPy's headers); False writes
        an FMU of sources only, which an importer builds.
    overwrite : bool, default=False
        Whether an existing ``path`` may be replaced.

    Returns
    -------
    path : Path
        The FMU written.

    Raises
    ------
    ValueError
        For a model :func:`write_c` refuses, an ``fmi_version`` other than "2.0" and "3.0",
        a path not ending in ``.fmu``, a missing or conflicting ``sampling_period``, output
        names of the wrong number or clashing with the inputs, ``units`` of a name that is no
        input or output.
    ImportError
        With ``binary``, when FMPy (the FMI headers) is not installed:
        ``pip install 'skhmmgmr[fmu]'``.
    RuntimeError
        With ``binary``, when there is no ``cc`` on the PATH or it fails.
    FileExistsError
        If ``path`` exists and ``overwrite`` is False.

    See Also
    --------
    write_c : The C filter alone.

    Notes
    -----
    See the user guide, "Using the model in a vehicle simulator", for loading the FMU in
    FMPy and what to expect from other importers.

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> import numpy as np
    >>> from skhmmgmr import HMMGMRRegressor
    >>> from skhmmgmr.export import write_fmu
    >>> X = np.cumsum(np.random.default_rng(0).normal(size=(300, 2)), axis=0) / 10
    >>> model = HMMGMRRegressor(n_states=2, random_state=0).fit(X, X.sum(axis=1))
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     path = write_fmu(model, Path(folder) / "driver.fmu", sampling_period=0.01,
    ...                      binary=False)
    ...     path.name
    'driver.fmu'
    """
    path = Path(path)
    if path.suffix != ".fmu":
        raise ValueError(f"path must name a .fmu file, got {str(path)!r}.")
    name = _model_identifier(name, path)
    check_output_paths([path], overwrite=overwrite, option="path")
    exported = read_filter(fitted)
    period = _sampling_period(fitted, sampling_period)
    outputs = _output_names(output_names, exported.n_outputs)
    description = (
        f"{type(fitted).__name__} of skhmmgmr: the causal HMM-GMR filter, one sample every "
        f"{period!r} s"
    )
    interface = describe(name, description, exported.input_names, outputs, units, period)
    headers = fmi_headers() if binary else None
    with tempfile.TemporaryDirectory() as folder:
        folder = Path(folder)
        (folder / "sources").mkdir()
        generated = write_c(fitted, folder / "sources", name=name)
        c_texts = [p.read_text() for p in generated]
        interface = replace(interface, token=_token([*c_texts, fmi_version, repr(interface)]))
        sources = {p.name: text for p, text in zip(generated, c_texts, strict=True)}
        sources[wrapper_name(name, fmi_version)] = wrapper(interface, fmi_version)
        compiled = [n for n in sources if n.endswith(".c")]
        if fmi_version == "3.0":
            sources["buildDescription.xml"] = build_description(interface, compiled)
        for file_name, text in sources.items():
            (folder / "sources" / file_name).write_text(text)
        entries = {f"sources/{n}": text.encode() for n, text in sources.items()}
        entries["modelDescription.xml"] = model_description(
            interface, fmi_version, compiled
        ).encode()
        if binary:
            target = _binary_path(name, fmi_version)
            entries[target] = _compile(folder, compiled, target, headers)
    return write_atomically(path, _archive(entries))
