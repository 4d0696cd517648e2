"""``write_c``: the causal filter of a fitted model as C99 source, for embedded targets."""

from ._c import write_c

__all__ = ["write_c"]
