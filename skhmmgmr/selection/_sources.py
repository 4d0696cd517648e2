"""Relevance sources of the framework: the selectors whose choices are counted per feature.

The thesis counts two sources, the exhaustive wrapper on the filter's top features and the
forward wrapper on all candidates (Section IV-C). :func:`~skhmmgmr.select_parameters` takes any
mapping of names to sources; these are the rules it fits and reads them by.
"""

import inspect
from dataclasses import dataclass

import pandas as pd
from sklearn.base import clone

from .._core._compat import (
    HasMethods,
    StrOptions,
    _routing_enabled,
    validate_parameter_constraints,
)
from ._candidates import feature_relevance
from ._selectors._exhaustive import ExhaustiveFeatureSelector
from ._selectors._forward import ForwardFeatureSelector

FEATURE_SCOPES = ("all", "top")
SOURCE_CONSTRAINTS = {
    "selector": [HasMethods(["fit"])],
    "features": [StrOptions(set(FEATURE_SCOPES))],
}


@dataclass(frozen=True)
class RelevanceSource:
    """A selector whose choices :func:`~skhmmgmr.select_parameters` counts per feature.

    Parameters
    ----------
    selector : selector estimator
        Unfitted; the framework fits a clone. Any scikit-learn selector works: the package's
        wrappers give one best subset per validation recording and trade-off (their
        ``best_subsets``); any other selector gives its selected features
        (``get_feature_names_out``) as one subset for every trade-off.
    features : {"all", "top"}, default="all"
        The columns the selector sees: every candidate feature, or the filter's top ``n_top``
        (as the thesis' exhaustive wrapper).

    Examples
    --------
    >>> from sklearn.feature_selection import SelectKBest, f_regression
    >>> from skhmmgmr.selection import RelevanceSource
    >>> RelevanceSource(SelectKBest(f_regression, k=3), features="top").features
    'top'
    """

    selector: object
    features: str = "all"

    def __post_init__(self):
        parameters = {"selector": self.selector, "features": self.features}
        validate_parameter_constraints(
            SOURCE_CONSTRAINTS, parameters, caller_name="RelevanceSource"
        )


def thesis_sources(estimator, *, max_subset_size=None, tol=0.01):
    """The thesis' two sources: exhaustive on the top features, forward per recording on all."""
    return {
        "exhaustive": RelevanceSource(
            ExhaustiveFeatureSelector(estimator, max_features=max_subset_size), features="top"
        ),
        "forward": RelevanceSource(
            ForwardFeatureSelector(estimator, mode="per_recording", tol=tol), features="all"
        ),
    }


def check_sources(sources):
    """The sources of a mapping as ``{name: RelevanceSource}`` (a bare selector sees every
    feature)."""
    if not sources:
        raise ValueError("relevance_sources must be a non-empty mapping name -> selector")
    checked = {}
    for name, source in sources.items():
        if not isinstance(name, str) or not name or name == "combined":
            raise ValueError(
                f"relevance source names must be non-empty strings other than "
                f"'combined', got {name!r}"
            )
        checked[name] = source if isinstance(source, RelevanceSource) else RelevanceSource(source)
    return checked


def fit_source(source, X, y, groups, *, shared):
    """Fit a clone of ``source.selector`` on ``X`` (the columns it sees).

    Of ``shared`` (cv, trade-off weights, sampling period, jobs, cache, verbosity, the mapped
    trade-offs, the search) the selector receives the parameters it has; ``groups`` goes to
    ``fit`` when its ``fit`` takes it, or takes ``**params`` with metadata routing on.
    """
    selector = clone(source.selector)
    own = selector.get_params(deep=False)
    selector.set_params(**{key: value for key, value in shared.items() if key in own})
    parameters = inspect.signature(selector.fit).parameters
    takes_params = any(p.kind is inspect.Parameter.VAR_KEYWORD for p in parameters.values())
    # A scikit-learn meta-estimator (SequentialFeatureSelector...) routes groups to its
    # splitter and scorer when metadata routing is on.
    if "groups" in parameters or (takes_params and _routing_enabled()):
        return selector.fit(X, y, groups=groups)
    return selector.fit(X, y)


def source_relevance(selector, trade_offs, features):
    """Feature counts of a fitted source for every trade-off (:func:`feature_relevance`)."""
    if hasattr(selector, "best_subsets"):
        return feature_relevance(selector, trade_offs, features=features)
    chosen = set(selector.get_feature_names_out())
    subset = tuple(f for f in features if f in chosen)
    return feature_relevance(_one_subset(subset, trade_offs), trade_offs, features=features)


def _one_subset(subset, trade_offs):
    return pd.DataFrame(
        {"trade_off": list(trade_offs), "recording": 0, "subset": [subset] * len(trade_offs)}
    )


def source_tables(name, selector):
    """The tables a fitted source leaves in the report: ``results_`` and ``paths_`` when it
    has them, else its selected features."""
    import pandas as pd

    tables = {}
    for attribute in ("results_", "paths_"):
        table = getattr(selector, attribute, None)
        if isinstance(table, pd.DataFrame):
            tables[f"{name}_{attribute.rstrip('_')}"] = table
    if not tables:
        tables[f"{name}_selected"] = pd.DataFrame({"feature": selector.get_feature_names_out()})
    return tables
