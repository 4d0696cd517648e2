"""Shared parameters read the same in every public class that takes them."""

import inspect

import pytest

import skhmmgmr
from skhmmgmr import feature_selection, metrics, selection, state_selection
from skhmmgmr._docstrings import SHARED_GROUPS, SHARED_PARAMETERS, fill_shared_parameters

# A parameter that only shares its name with a shared one, and what it means there instead.
SAME_NAME_OTHER_MEANING = {
    ("HMMGMRRegressor", "verbose"): "prints the log-likelihood of every EM iteration",
}


def public_classes():
    found = {}
    for module in (skhmmgmr, metrics, feature_selection, selection, state_selection):
        for name in getattr(module, "__all__", []):
            obj = getattr(module, name)
            if inspect.isclass(obj) and obj.__doc__ and "__init__" in vars(obj):
                found[obj.__qualname__] = obj
    return sorted(found.values(), key=lambda cls: cls.__qualname__)


def takers(key):
    names = [n.strip() for n in key.split(",")]
    return [
        cls
        for cls in public_classes()
        if set(names) <= set(inspect.signature(cls.__init__).parameters)
    ]


@pytest.mark.parametrize("key", sorted(SHARED_PARAMETERS))
def test_every_class_taking_a_shared_parameter_describes_it_with_the_shared_entry(key):
    classes = takers(key)
    assert classes, f"no public class takes the shared parameter(s) {key}"
    for cls in classes:
        if (cls.__qualname__, key) in SAME_NAME_OTHER_MEANING:
            continue
        described = SHARED_PARAMETERS[key] in inspect.cleandoc(cls.__doc__)
        assert described, (
            f"{cls.__qualname__} describes {key} otherwise than the shared entry "
            f"(write the line '{{{key}}}' in its Parameters section)"
        )


def test_no_placeholder_is_left_in_a_public_docstring():
    for cls in public_classes():
        for key in [*SHARED_PARAMETERS, *SHARED_GROUPS]:
            assert "{" + key + "}" not in cls.__doc__, (cls, key)


def test_the_filler_replaces_registered_names_only_and_keeps_the_indentation():
    @fill_shared_parameters
    class Example:
        """Title.

        Parameters
        ----------
        {verbose}
        mode : {"a", "b"}
            Two options.
        {not_a_shared_parameter}
        """

    doc = inspect.cleandoc(Example.__doc__)
    assert SHARED_PARAMETERS["verbose"] in doc
    assert 'mode : {"a", "b"}' in doc
    assert "{not_a_shared_parameter}" in doc


def test_a_group_placeholder_expands_to_its_entries_in_order():
    @fill_shared_parameters
    class Example:
        """Title.

        Parameters
        ----------
        {search parameters}
        """

    doc = inspect.cleandoc(Example.__doc__)
    positions = [doc.index(SHARED_PARAMETERS[key]) for key in SHARED_GROUPS["search parameters"]]
    assert positions == sorted(positions)
    assert "{search parameters}" not in doc
