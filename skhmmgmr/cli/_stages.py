"""The stages of a command's run: one progress bar each, and their times.

On a terminal every stage has one tqdm bar of its own, left on screen when the stage ends, so
that no bar overwrites another; a stage that runs many loops of the package (the parameter
selection's wrappers, candidates and state sweep) gathers them into its one bar
(:func:`~skhmmgmr._core._progress.reporting_to`). Elsewhere (stderr redirected to a file or a
pipe) every stage writes one plain line when it ends. ``--quiet`` shows neither.

Every stage's wall time and the CPU time of this process are kept (:attr:`Stages.timings`)
for the report; the CPU time of joblib's worker processes is not in it.
"""

import contextlib
import sys
import time

from .._core._progress import reporting_to


class _StageBar:
    """The bar of one stage: tqdm on a terminal, nothing until its end line elsewhere."""

    def __init__(self, name, total, *, shown, terminal, stream):
        self.name, self.stream, self.shown = name, stream, shown
        self.done, self.total, self.detail = 0, total or 0, ""
        self.bar = None
        if shown and terminal:
            from tqdm import tqdm

            self.bar = tqdm(total=total, desc=name, file=stream, leave=True, dynamic_ncols=True)

    def update(self, n=1, detail=None):
        """Count ``n`` more steps done; ``detail`` says which (shown beside the bar)."""
        self.done += n
        if detail is not None:
            self.detail = detail
        if self.bar is not None:
            if detail is not None:
                self.bar.set_postfix_str(detail, refresh=False)
            self.bar.update(n)

    def track(self, iterable, *, total, desc):
        """The items of ``iterable``, counted as steps of this stage (one loop of it)."""
        self.total += total
        if self.bar is not None:
            self.bar.total = self.total
            self.bar.set_postfix_str(desc, refresh=False)
            self.bar.refresh()
        for item in iterable:
            yield item
            self.update()

    def close(self, seconds):
        if self.bar is not None:
            self.bar.set_postfix_str(f"{seconds:.1f} s")
            self.bar.close()
        elif self.shown:
            steps = f"{self.done}/{self.total} steps" if self.total else f"{self.done} steps"
            detail = f", {self.detail}" if self.detail else ""
            print(f"{self.name}: done, {steps}{detail} ({seconds:.1f} s)", file=self.stream)
            self.stream.flush()


class Stages:
    """The stages of one run: ``with stages.stage("simulation", total=1) as bar: ...``.

    Parameters
    ----------
    quiet : bool
        Show no bar and no line.
    stream : file, default=sys.stderr
        Where the bars (on a terminal) or the end lines (elsewhere) go.
    """

    def __init__(self, quiet=False, stream=None):
        self.stream = sys.stderr if stream is None else stream
        self.shown = not quiet
        isatty = getattr(self.stream, "isatty", None)
        self.terminal = bool(isatty and isatty())
        #: stage -> {"wall": seconds, "cpu": seconds of this process}
        self.timings = {}

    @contextlib.contextmanager
    def stage(self, name, total=None):
        """A stage: its bar (``update`` it, or let the package's loops in it count), timed."""
        bar = _StageBar(name, total, shown=self.shown, terminal=self.terminal, stream=self.stream)
        wall, cpu = time.perf_counter(), time.process_time()
        with reporting_to(bar):
            yield bar
        seconds = time.perf_counter() - wall
        self.timings[name] = {"wall": seconds, "cpu": time.process_time() - cpu}
        bar.close(seconds)
