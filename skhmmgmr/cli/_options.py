"""What the commands share: the help format, the options of data and outputs, how option
values are read, and the messages of a run.

Option values are checked when they are parsed, before any file is read: numbers must be
finite, and an option that sets a parameter of the package's models is checked by that
parameter's own rule (its ``_parameter_constraints``, see :func:`checked_by`), so that the
command line and the Python API refuse the same values with the same words.
"""

import argparse
import math

from .._core._compat import InvalidParameterError, validate_parameter_constraints
from .._core._schema import RECORDING, TARGET, TIME

# The --time value of fit and predict that takes the rows in file order (no time column).
NO_TIME = "none"


class HelpFormatter(argparse.ArgumentDefaultsHelpFormatter):
    """Every option's help ends with its default, unless it states it (as options whose
    default is None, decided at run time, do)."""

    def _get_help_string(self, action):
        if action.default is None or "(default" in (action.help or ""):
            return action.help
        return super()._get_help_string(action)


def log(args, message):
    if not getattr(args, "quiet", False):
        print(message, flush=True)


def option_name(name):
    """The option of a parameter: ``velocity_filter`` -> ``--velocity-filter``."""
    return f"--{name.replace('_', '-')}"


def finite_float(text):
    """A number option's value: a finite float (``inf`` and ``nan`` are refused here, not
    after a run)."""
    value = float(text)
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"must be a finite number, got {text!r}")
    return value


def setting(text):
    """A derived input's or a read-out's setting: a number, 'none' or 'auto' (chosen in fit);
    the parameter's own rule checks the number (:func:`checked_by`)."""
    if text.lower() in ("auto", "none"):
        return None if text.lower() == "none" else "auto"
    return float(text)


def checked_by(parse, owner, parameter):
    """An option type: ``parse`` the text, then check the value by the rule of ``owner``'s
    ``parameter`` (its ``_parameter_constraints`` entry), as ``owner.fit`` would."""
    constraints = {parameter: owner._parameter_constraints[parameter]}

    def read(text):
        value = parse(text)
        try:
            validate_parameter_constraints(
                constraints, {parameter: value}, caller_name=owner.__name__
            )
        except InvalidParameterError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None
        return value

    read.__name__ = parse.__name__  # argparse names the type in its own errors
    return read


def add_data_options(parser, *, file_order=False):
    parser.add_argument("--target", default=TARGET, help="target column")
    parser.add_argument("--recording", default=RECORDING, help="recording-id column")
    text = "time column [s]: rows are sorted by it within each recording; never an input"
    if file_order:
        text += f" ('{NO_TIME}': no time column, the rows are taken in file order)"
    parser.add_argument("--time", default=TIME, help=text)


def add_output_options(parser, default, text):
    parser.add_argument("--output", default=default, help=text)
    text = "replace an existing output that is not a skhmmgmr report (never an input)"
    parser.add_argument("--overwrite", action="store_true", help=text)
