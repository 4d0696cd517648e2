"""Shared parameters read the same in every public class that takes them."""

import inspect

import pytest

import skhmmgmr
from skhmmgmr import feature_selection, metrics, selection, state_selection
from skhmmgmr._core._docstrings import SHARED_GROUPS, SHARED_PARAMETERS, fill_shared_parameters

# A parameter that only shares its name with a shared one, and what it means there instead.
SAME_NAME_OTHER_MEANING = {
    ("HMMGMRRegressor", "verbose"): "prints the log-likelihood of every EM iteration",
    ("HierarchicalHMMGMRRegressor", "verbose"): "prints the joint EM log-likelihoods",
    ("compare_subsets", "groups"): "required: the comparison validates whole recordings",
    ("select_parameters", "estimator"): "a template whose features and n_states it selects",
}


def public_objects():
    """Public classes (their parameters are those of ``__init__``) and public functions."""
    found = {}
    for module in (skhmmgmr, metrics, feature_selection, selection, state_selection):
        for name in getattr(module, "__all__", []):
            obj = getattr(module, name)
            if not obj.__doc__:
                continue
            if (inspect.isclass(obj) and "__init__" in vars(obj)) or inspect.isfunction(obj):
                found[obj.__qualname__] = obj
    return sorted(found.values(), key=lambda obj: obj.__qualname__)


def parameters(obj):
    return set(inspect.signature(obj.__init__ if inspect.isclass(obj) else obj).parameters)


def takers(key):
    names = [n.strip() for n in key.split(",")]
    return [obj for obj in public_objects() if set(names) <= parameters(obj)]


@pytest.mark.parametrize("key", sorted(SHARED_PARAMETERS))
def test_every_class_taking_a_shared_parameter_describes_it_with_the_shared_entry(key):
    objects = takers(key)
    assert objects, f"no public class or function takes the shared parameter(s) {key}"
    otherwise = [
        obj.__qualname__
        for obj in objects
        if (obj.__qualname__, key) not in SAME_NAME_OTHER_MEANING
        and SHARED_PARAMETERS[key] not in inspect.cleandoc(obj.__doc__)
    ]
    assert not otherwise, (
        f"{', '.join(otherwise)} describe(s) {key} otherwise than the shared entry "
        f"(write the line '{{{key}}}' in the Parameters section)"
    )


def test_no_placeholder_is_left_in_a_public_docstring():
    for cls in public_objects():
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
    keys = [k if isinstance(k, str) else k[0] for k in SHARED_GROUPS["search parameters"]]
    positions = [doc.index(SHARED_PARAMETERS[key]) for key in keys]
    assert positions == sorted(positions)
    assert "{search parameters}" not in doc
