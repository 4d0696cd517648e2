"""Greedy forward selection: one path per (trade-off, recording or average), and the scores it
reads from a frozen table of evaluated subsets."""

import numpy as np
import pandas as pd

from .._search._decisions import possible_winners, score_bounds
from .._search._score_tables import relative_gain


class ForwardPath:
    """One greedy forward path: add the feature with the lowest score while it gains > tol."""

    def __init__(self, n_candidates, *, tol, max_features):
        self.n_candidates = n_candidates
        self.tol = tol
        self.max_features = max_features
        self.selected = ()
        self.score = np.inf
        self.active = True
        self.history = []

    def candidates(self):
        return [
            tuple(sorted((*self.selected, j)))
            for j in range(self.n_candidates)
            if j not in self.selected
        ]

    def step(self, score_of):
        options = [
            (score_of(tuple(sorted((*self.selected, j)))), j)
            for j in range(self.n_candidates)
            if j not in self.selected
        ]
        best_score, feature = min(options)
        gain = relative_gain(self.score, best_score)
        accepted = gain > self.tol
        self.history.append(
            {
                "step": len(self.history) + 1,
                "feature": feature,
                "subset": tuple(sorted((*self.selected, feature))),
                "performance_score": best_score,
                "gain": gain,
                "accepted": accepted,
            }
        )
        if accepted:
            self.selected = (*self.selected, feature)
            self.score = best_score
        done = len(self.selected) >= min(self.max_features, self.n_candidates)
        self.active = accepted and not done


def settled_prefix(path, score_of, exact, tolerance):
    """``(features, settled)``: the features a traced ``path`` selected before its first
    decision that the bound leaves open, and whether it left none open.

    A step's decision is open when a screened option's score within ``tolerance``
    (relative; the subsets in ``exact`` are exact) could make another option the best, or
    move the best's gain across the path's ``tol``, or when the path took another option
    than the scores now known make the best (it was traced before some were confirmed).
    The path only adds features, so those selected before an open decision are in its
    final subset whatever the decision.
    """
    selected, previous = (), None  # the subset held, and its score's bounds
    for entry in path.history:
        options = [
            tuple(sorted((*selected, j))) for j in range(path.n_candidates) if j not in selected
        ]
        values = np.array([score_of(s) for s in options])
        flags = np.array([s in exact for s in options])
        possible = possible_winners(values, flags, tolerance)
        best = int(np.argmin(values))
        if possible.sum() > 1 and not flags[possible].all():
            return selected, False
        if options[best] != entry["subset"]:  # traced on scores confirmed since
            return selected, False
        low, high = score_bounds(values[best], flags[best], tolerance)
        if previous is not None:
            gains = relative_gain(previous[0], high), relative_gain(previous[1], low)
            if min(gains) <= path.tol < max(gains):
                return selected, False
        if not entry["accepted"]:
            break
        selected, previous = entry["subset"], (low, high)
    return selected, True


class FrozenScores:
    """Performance scores of evaluated subsets with the D.5 sums frozen on a reference set.

    Each term is divided, per recording, by its sum over the reference subsets, so that scores
    of subsets evaluated later stay comparable with earlier ones.
    """

    def __init__(self, recordings):
        self.recordings = recordings
        self.terms = {}

    def missing(self, subsets):
        return [s for s in dict.fromkeys(subsets) if s not in self.terms]

    def add(self, subsets, table):
        """The terms of ``subsets`` from their ``table`` (known terms are replaced)."""
        parts = table.groupby("subset", sort=False)
        for subset, (_, part) in zip(subsets, parts, strict=True):
            part = part.set_index("recording").loc[self.recordings]
            self.terms[subset] = (
                np.abs(100.0 - part["accuracy"].to_numpy()),
                np.abs(part["smoothness"].to_numpy()),
            )

    def freeze(self, reference):
        totals = np.sum([self.terms[s] for s in reference], axis=0)
        self.scales = np.where(totals > 0, totals, np.inf)

    def scorer(self, accuracy_weight, smoothness_weight, positions):
        """Function subset -> mean score over the recordings at ``positions``."""

        def score_of(subset):
            loss, rough = self.terms[subset]
            per_recording = (
                accuracy_weight * loss / self.scales[0] + smoothness_weight * rough / self.scales[1]
            )
            return float(np.mean(per_recording[positions]))

        return score_of


def paths_table(paths, names, recordings):
    """One row per step of every forward path ``{(trade_off, path_id): ForwardPath}``."""
    rows = []
    for (label, path_id), path in paths.items():
        name = "average" if path_id == "average" else recordings[path_id]
        for entry in path.history:
            rows.append(
                {
                    "trade_off": label,
                    "path": name,
                    **entry,
                    "feature": names[entry["feature"]],
                    "subset": tuple(names[list(entry["subset"])]),
                }
            )
    return pd.DataFrame(rows)
