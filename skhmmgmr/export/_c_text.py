"""Python values as C99 text: numbers in the filter's arithmetic, ``static const`` arrays,
string literals and comments that nothing in them can break.

The generated code must build warning-free with ``cc -std=c99 -pedantic -Wall -Wextra
-Werror`` (and, for ``dtype="float32"``, ``-Wdouble-promotion``) whatever the model holds:

- a number is written so that it reads back exactly in the filter's type: ``repr`` of the
  double, or of the single-precision value with an ``f`` suffix; a value beyond the range of
  ``float`` is refused (:func:`check_float32`) rather than written as an infinity;
- a string (a feature name) longer than the 4,095 characters C99 compilers must support in a
  string literal is written as a brace-enclosed array of character codes;
- a comment holds no ``*/`` nor ``/*`` and no two consecutive ``?`` (a trigraph such as ``??/``
  would turn into a backslash, and at the end of a line join it to the next).
"""

import re
import textwrap

import numpy as np

# The C text of each arithmetic: its type, the suffix of its literals, its math.h functions
# and the standardised-input magnitude from which a sample is out of range (the policy's
# 1e100 in double; in float, within float's range: the squares of its terms overflow first).
TYPES = {
    "float64": {
        "real": "double",
        "suffix": "",
        "exp": "exp",
        "sqrt": "sqrt",
        "tanh": "tanh",
        "pow": "pow",
        "fabs": "fabs",
        "max_standardised": 1e100,
    },
    "float32": {
        "real": "float",
        "suffix": "f",
        "exp": "expf",
        "sqrt": "sqrtf",
        "tanh": "tanhf",
        "pow": "powf",
        "fabs": "fabsf",
        "max_standardised": 1e30,
    },
}
_PER_LINE = 4
# C99 5.2.4.1: 4095 characters in a string literal, and in a logical source line
_LONGEST_STRING = 4095
_CHARS_PER_LINE = 16
_FLOAT32_MAX = float(np.finfo(np.float32).max)


def number(value, dtype):
    """A C literal of ``value`` in the arithmetic ``dtype`` that reads back exactly."""
    if dtype == "float32":
        return repr(float(np.float32(value))) + "f"
    return repr(float(value))


def array(name, dtype, values, comment=None):
    """A ``static const`` array definition holding ``values`` (flattened) in ``dtype``."""
    numbers = [number(v, dtype) for v in np.ravel(values)]
    lines = [", ".join(numbers[i : i + _PER_LINE]) for i in range(0, len(numbers), _PER_LINE)]
    body = ",\n    ".join(lines)
    head = f"/* {comment} */\n" if comment else ""
    real = TYPES[dtype]["real"]
    return f"{head}static const {real} {name}[{len(numbers)}] = {{\n    {body}\n}};\n"


# the model's numbers the filter divides by (beside the ``*scale`` ones)
DIVISORS = ("friction_velocity", "friction_widths", "friction_radii")


def check_float32(named_values):
    """Refuse, naming it, a value of ``named_values`` ({name: array-like}) that single
    precision cannot hold: beyond ``float``'s range (it would be written as an infinity) or,
    for a ``*scale``, ``friction_velocity``, ``friction_widths`` or ``friction_radii``
    divisor, non-zero but rounding to zero."""
    for name, values in named_values.items():
        values = np.ravel(np.asarray(values, dtype=float))
        beyond = np.abs(values) > _FLOAT32_MAX
        if name.endswith("scale") or name in DIVISORS:
            beyond |= (values != 0) & (values.astype(np.float32) == 0)
        if beyond.any():
            value = float(values[np.flatnonzero(beyond)[0]])
            raise ValueError(
                f"write_c(dtype='float32'): the model's {name} holds {value!r}, which single "
                f"precision cannot hold (float's range is {_FLOAT32_MAX:.4g} down to "
                f"{float(np.finfo(np.float32).smallest_subnormal):.4g}); export it with "
                "dtype='float64', or fit on inputs in other units."
            )


def string(text, name):
    """A definition of the ``static const char`` array ``name`` holding ``text`` (UTF-8):
    a string literal (anything but plain characters as octal escapes), or, beyond
    4,095 bytes, the codes of its bytes."""
    data = str(text).encode("utf-8")
    if len(data) <= _LONGEST_STRING:
        return f"static const char {name}[] = {_literal(data)};\n"
    codes = [str(byte) for byte in data] + ["0"]
    lines = [
        ", ".join(codes[i : i + _CHARS_PER_LINE]) for i in range(0, len(codes), _CHARS_PER_LINE)
    ]
    body = ",\n    ".join(lines)
    return f"static const char {name}[{len(codes)}] = {{\n    {body}\n}};\n"


_PLAIN = frozenset("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789 _-.,:;()[]/+*=")


def _literal(data):
    return '"' + "".join(chr(b) if chr(b) in _PLAIN else f"\\{b:03o}" for b in data) + '"'


def comment(text, first):
    """``text`` wrapped into C comment lines, the first starting with ``first``; nothing in it
    can end the comment or form a trigraph."""
    text = text.replace("*/", "* /").replace("/*", "/ *")
    lines = textwrap.wrap(_no_trigraph(text), 96, initial_indent=first, subsequent_indent=" *   ")
    # the wrap may put a "?" at the end of one line and another at the start of the next:
    # harmless (a line break lies between), but a "??" within a line is not
    return _no_trigraph("\n".join(lines))[1:]  # the caller writes the first " "


def _no_trigraph(text):
    """``text`` with a space after every ``?`` that another follows."""
    return re.sub(r"\?(?=\?)", "? ", text)
