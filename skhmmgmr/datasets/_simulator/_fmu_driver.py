"""A Functional Mock-up Unit at the wheel of :func:`~skhmmgmr.datasets.drive`, through FMPy.

:class:`FMUDriver` loads a co-simulation FMU (FMI 2.0 or 3.0; the ones
:func:`skhmmgmr.export.write_fmu` writes, or any other whose inputs are sensed features), and
turns it into the torque function ``drive`` calls once per sample: set the FMU's inputs to the
sensed row (found by name among :data:`~skhmmgmr.datasets.FEATURE_NAMES`), take one
communication step of the sampling period, read the torque. The torque is the output named
``driver_torque``, else the FMU's first real output. The FMU's default step size, when it has
one, must be the drive's sampling period.

FMPy is imported here only, when a drive is given an FMU (the extra ``skhmmgmr[fmu]``).
"""

import math
import shutil
import tempfile
from pathlib import Path

import numpy as np

from ..._core._schema import FEATURE_NAMES, TARGET


def is_fmu(driver):
    """Whether ``drive`` was given an FMU: a path-like, or a string ending in ``.fmu``."""
    if isinstance(driver, str):
        return driver.lower().endswith(".fmu")
    return hasattr(driver, "__fspath__")


def _fmpy():
    try:
        import fmpy
    except ImportError:
        raise ImportError(
            "drive runs an FMU through FMPy, which is not installed: pip install 'skhmmgmr[fmu]'."
        ) from None
    return fmpy


class FMUDriver:
    """One instance of an FMU that steps once per sample; call it with a sensed row.

    Parameters
    ----------
    path : path-like
        The ``.fmu`` file.
    sampling_rate : float
        Samples per second of the drive: the communication step is its inverse.
    """

    def __init__(self, path, sampling_rate):
        fmpy = _fmpy()
        self.path = Path(path)
        if not self.path.is_file():
            raise FileNotFoundError(f"driver: the FMU {str(self.path)!r} does not exist.")
        self.name = self.path.name
        self.period = 1.0 / sampling_rate
        description = fmpy.read_model_description(str(self.path))
        self._check(description, sampling_rate)
        variables = description.modelVariables
        inputs = [v for v in variables if v.causality == "input"]
        unknown = [v.name for v in inputs if v.name not in FEATURE_NAMES]
        if unknown:
            raise ValueError(
                f"the FMU {self.name} reads {unknown}, which the simulator does not sense; it "
                f"senses {list(FEATURE_NAMES)}."
            )
        real = ("Real", "Float64")
        outputs = [v for v in variables if v.causality == "output" and v.type in real]
        if not outputs:
            raise ValueError(f"the FMU {self.name} has no real output to take as the torque.")
        torque = next((v for v in outputs if v.name == TARGET), outputs[0])
        self.positions = np.array([FEATURE_NAMES.index(v.name) for v in inputs], dtype=int)
        self._inputs = [v.valueReference for v in inputs]
        self._torque = [torque.valueReference]
        self._folder = tempfile.mkdtemp(prefix="skhmmgmr-fmu-")
        try:
            fmpy.extract(str(self.path), self._folder)
            self._fmu = fmpy.instantiate_fmu(self._folder, description, fmi_type="CoSimulation")
        except BaseException:
            shutil.rmtree(self._folder, ignore_errors=True)
            raise
        if description.fmiVersion == "2.0":
            self._set, self._get = self._fmu.setReal, self._fmu.getReal
            self._fmu.setupExperiment(startTime=0.0)
            self._fmu.enterInitializationMode()
        else:
            self._set, self._get = self._fmu.setFloat64, self._fmu.getFloat64
            self._fmu.enterInitializationMode(startTime=0.0)
        self._fmu.exitInitializationMode()
        self._step = 0

    def _check(self, description, sampling_rate):
        if description.fmiVersion not in ("2.0", "3.0") or description.coSimulation is None:
            raise ValueError(
                f"the FMU {self.name} is not an FMI 2.0 or 3.0 co-simulation FMU (FMI "
                f"{description.fmiVersion}); drive steps co-simulation FMUs."
            )
        experiment = description.defaultExperiment
        step = None if experiment is None else experiment.stepSize
        if step is not None and not math.isclose(float(step), self.period, rel_tol=1e-9):
            raise ValueError(
                f"the FMU {self.name} steps every {float(step)!r} s (its default experiment) "
                f"and the drive samples every {self.period!r} s: drive with "
                f"sampling_rate={1.0 / float(step)!r}."
            )

    def __call__(self, row):
        """The torque of the sensed row ``row`` (the features in the order of FEATURE_NAMES):
        one communication step from the row's time."""
        self._set(self._inputs, row[self.positions].tolist())
        self._fmu.doStep(
            currentCommunicationPoint=self._step * self.period, communicationStepSize=self.period
        )
        self._step += 1
        return self._get(self._torque)[0]

    def close(self):
        """End the instance, unload the binary and remove the extracted files."""
        try:
            try:
                self._fmu.terminate()
            finally:
                self._fmu.freeInstance()
        finally:
            shutil.rmtree(self._folder, ignore_errors=True)
