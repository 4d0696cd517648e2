"""The causal filter of a fitted model for other targets: ``write_c`` (C99 source, for embedded
targets) and ``write_fmu`` (a Functional Mock-up Unit, for vehicle simulators)."""

from ._c import write_c
from ._fmu import write_fmu

__all__ = ["write_c", "write_fmu"]
