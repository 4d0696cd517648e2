"""The parameters every selector that searches over recordings shares are defined once, in
``RecordingSearchMixin``: their constraints, their defaults, their storage and their text."""

import inspect

import pytest
from sklearn.base import clone

from skhmmgmr import ExhaustiveFeatureSelector, ForwardFeatureSelector, StateSelector
from skhmmgmr._core._docstrings import SHARED_GROUPS, SHARED_PARAMETERS
from skhmmgmr.selection._search.base import RecordingSearchMixin

SELECTORS = (ExhaustiveFeatureSelector, ForwardFeatureSelector, StateSelector)


def defaults(cls):
    return {
        name: p.default
        for name, p in inspect.signature(cls.__init__).parameters.items()
        if name != "self"
    }


SHARED = defaults(RecordingSearchMixin)


def test_the_mixin_describes_what_it_constrains():
    group = [
        item if isinstance(item, str) else item[0] for item in SHARED_GROUPS["search parameters"]
    ]
    described = {"estimator"} | {name.strip() for key in group for name in key.split(",")}
    assert set(RecordingSearchMixin._parameter_constraints) == described == set(SHARED)
    doc = inspect.cleandoc(RecordingSearchMixin.__doc__)
    for key in ["estimator", *group]:
        assert SHARED_PARAMETERS[key] in doc


@pytest.mark.parametrize("cls", SELECTORS, ids=lambda cls: cls.__name__)
def test_a_selector_takes_the_shared_parameters_as_the_mixin_defines_them(cls):
    assert issubclass(cls, RecordingSearchMixin)
    own = defaults(cls)
    assert {name: own[name] for name in SHARED} == SHARED  # the same names and defaults
    for name, constraint in RecordingSearchMixin._parameter_constraints.items():
        assert cls._parameter_constraints[name] is constraint
    # the shared text, once per selector (the group's placeholder, filled)
    doc = inspect.cleandoc(cls.__doc__)
    assert doc.count(SHARED_PARAMETERS["memory"]) == 1
    # every parameter, shared or its own, reaches the instance unchanged (clone checks it)
    values = {
        "cv": 3,
        "accuracy_weight": 0.7,
        "smoothness_weight": 0.3,
        "sampling_period": 0.05,
        "n_jobs": 2,
        "memory": "cache",
        "verbose": 1,
    }
    selector = cls(**values)
    assert {name: getattr(selector, name) for name in values} == values
    assert clone(selector).get_params() == selector.get_params()
