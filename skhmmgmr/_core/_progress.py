"""Progress bars: a loop's own tqdm bar, or one bar for a caller's whole stage.

A loop of the package (the models of a selection search) shows its own tqdm bar. A caller that
runs many such loops as one stage (the command line's "parameter selection", which runs the
framework's wrappers, candidates and state sweep) opens that stage with :func:`reporting_to`:
inside it, the loops advance the stage's one bar (its total grows by each loop's length)
instead of opening bars of their own, so that one bar stands for one stage and no bar
overwrites another.
"""

import contextlib
import contextvars

__all__ = ["progress_bar", "reporting_to"]

_STAGE = contextvars.ContextVar("skhmmgmr_progress_stage", default=None)


@contextlib.contextmanager
def reporting_to(stage):
    """Within the block, :func:`progress_bar` reports to ``stage``.

    ``stage`` has a method ``track(iterable, total, desc)`` that yields the items of
    ``iterable`` and counts them (adding ``total`` to the stage's own total first).
    """
    token = _STAGE.set(stage)
    try:
        yield stage
    finally:
        _STAGE.reset(token)


def progress_bar(iterable, *, total, desc, disable=False):
    """The items of ``iterable``, counted by a tqdm bar of their own or by the stage a caller
    opened (:func:`reporting_to`); ``disable``: counted by neither."""
    if disable:
        return iterable
    stage = _STAGE.get()
    if stage is not None:
        return stage.track(iterable, total=total, desc=desc)
    from tqdm.auto import tqdm

    return tqdm(iterable, total=total, desc=desc)
