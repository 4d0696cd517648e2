"""What an FMU of a fitted model declares: its variables, ``modelDescription.xml`` and, for FMI
3.0, ``buildDescription.xml``.

:func:`describe` lays out the variables of the co-simulation FMU that :func:`write_fmu
<skhmmgmr.export.write_fmu>` writes, as an :class:`FMUInterface`; the value references are the
same in both FMI versions and the generated wrapper (:mod:`._fmu_wrapper`) reads them from
there:

- ``0``: the independent variable ``time`` [s] (declared in FMI 3.0 only, which asks for one);
- ``1 .. n_inputs``: the raw inputs, in the fitted order, continuous (any signal can be
  connected to them; the FMU samples them at the start of every communication step and
  neither interpolates them nor asks for their derivatives), start value 0;
- then the estimate of every output, then its predictive standard deviation
  (``<output>_std``), both ``discrete`` (they change at communication points only) with
  ``initial="calculated"``;
- last, ``update_status`` (Integer / Int32): what the last update did, the return code of the
  generated ``<name>_update`` (0 filtered, 1 an input not finite, 2 an outlier: held), or -1
  when no step has been taken since the start or the last reset.

No output depends on the inputs of the same instant (``dependencies=""``): the update runs in
``doStep`` on the inputs set before it, so the outputs after ``doStep(t, h)`` are the estimate
of the sample taken at ``t``. An importer therefore sees no algebraic loop when the FMU's torque
feeds the vehicle whose states feed the FMU.

Units: a unit text of the package's schema (``FEATURE_UNITS``, ``TARGET_UNIT``) or given by the
caller is declared with its SI base units (``<BaseUnit>``) when :func:`base_units` can read it
(products and one quotient of ``m``, ``s``, ``rad``, ``kg``, ``N``, ``Nm`` with integer powers,
``1``); a variable whose unit it cannot read is declared without one.
"""

import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass

from .._core._schema import FEATURE_UNITS, TARGET, TARGET_UNIT
from .._version import __version__

#: Value reference of the independent variable ``time`` (FMI 3.0).
TIME_REFERENCE = 0
#: The status before any sample since the start or the last reset.
NO_SAMPLE = -1
STATUS_NAME = "update_status"
STD_SUFFIX = "_std"

# symbol -> exponents of the FMI base units (kg, m, s, A, K, mol, cd, rad)
_SYMBOLS = {
    "m": {"m": 1},
    "s": {"s": 1},
    "rad": {"rad": 1},
    "kg": {"kg": 1},
    "N": {"kg": 1, "m": 1, "s": -2},
    "Nm": {"kg": 1, "m": 2, "s": -2},
}
_FACTOR = re.compile(r"^([A-Za-z]+)(?:\^(-?\d+))?$")


def base_units(unit):
    """The SI base-unit exponents of a unit text (``"rad/s^2"`` -> ``{"rad": 1, "s": -2}``), or
    None when the text is not a product of known symbols over at most one quotient."""
    parts = str(unit).split("/")
    if len(parts) > 2 or not all(parts):
        return None
    exponents = {}
    for sign, part in zip((1, -1), parts, strict=False):
        if part == "1":
            continue
        for factor in part.split("."):
            match = _FACTOR.match(factor)
            if match is None or match.group(1) not in _SYMBOLS:
                return None
            power = sign * int(match.group(2) or 1)
            for base, exponent in _SYMBOLS[match.group(1)].items():
                exponents[base] = exponents.get(base, 0) + power * exponent
    return {base: exponent for base, exponent in exponents.items() if exponent}


@dataclass(frozen=True)
class FMUVariable:
    """One variable of the FMU: ``causality`` "input", "output" or "independent", ``kind``
    "real" or "integer", ``unit`` a unit text or None."""

    name: str
    value_reference: int
    causality: str
    kind: str
    unit: str | None
    description: str


@dataclass(frozen=True)
class FMUInterface:
    """The FMU's identity and variables (see the module docstring for the layout)."""

    model_identifier: str
    description: str
    sampling_period: float
    n_inputs: int
    n_outputs: int
    variables: tuple
    token: str = ""

    @property
    def first_input(self):
        return TIME_REFERENCE + 1

    @property
    def first_estimate(self):
        return self.first_input + self.n_inputs

    @property
    def first_std(self):
        return self.first_estimate + self.n_outputs

    @property
    def status_reference(self):
        return self.first_std + self.n_outputs


def describe(model_identifier, description, input_names, output_names, units, sampling_period):
    """The :class:`FMUInterface` (without its token) of a model with these inputs and outputs.

    ``units`` maps names to unit texts and completes the package's schema (the caller's win).

    Raises
    ------
    ValueError
        For two variables of the same name (an output named as an input, ``<output>_std`` or
        ``update_status`` taken), or a ``units`` name that is no input or output.
    """
    units = {str(name): str(unit) for name, unit in dict(units or {}).items()}
    unknown = sorted(set(units) - {*input_names, *output_names})
    if unknown:
        raise ValueError(
            f"units names {unknown}, which are neither inputs nor outputs of the model (inputs "
            f"{list(input_names)}, outputs {list(output_names)})"
        )
    known = {**FEATURE_UNITS, TARGET: TARGET_UNIT, **units}
    n_inputs, n_outputs = len(input_names), len(output_names)
    variables = [FMUVariable("time", TIME_REFERENCE, "independent", "real", "s", "Time")]
    reference = TIME_REFERENCE + 1
    for position, name in enumerate(input_names):
        text = f"Input {position + 1} of {n_inputs} of the model, sampled at every step"
        variables.append(FMUVariable(name, reference, "input", "real", known.get(name), text))
        reference += 1
    for name in output_names:
        text = f"Estimate of {name} at the sample of the last step (held on a held sample)"
        variables.append(FMUVariable(name, reference, "output", "real", known.get(name), text))
        reference += 1
    for name in output_names:
        text = f"Predictive standard deviation of {name} at the sample of the last step"
        std = FMUVariable(name + STD_SUFFIX, reference, "output", "real", known.get(name), text)
        variables.append(std)
        reference += 1
    text = (
        "What the last step's update did: 0 filtered, 1 held (an input not finite), 2 held "
        f"(an outlier), {NO_SAMPLE} no step since the start or the last reset"
    )
    variables.append(FMUVariable(STATUS_NAME, reference, "output", "integer", None, text))
    seen = {}
    for variable in variables:
        if variable.name in seen:
            raise ValueError(
                f"the FMU would have two variables named {variable.name!r} (the "
                f"{seen[variable.name]} and the {variable.causality}); rename the outputs "
                "with output_names"
            )
        seen[variable.name] = variable.causality
    return FMUInterface(
        model_identifier,
        description,
        float(sampling_period),
        n_inputs,
        n_outputs,
        tuple(variables),
    )


def _number(value):
    return repr(float(value))


def _unit_definitions(parent, declared):
    units = sorted({_unit(v) for v in declared} - {None})
    if units:
        definitions = ET.SubElement(parent, "UnitDefinitions")
        for unit in units:
            element = ET.SubElement(definitions, "Unit", name=unit)
            ET.SubElement(element, "BaseUnit", {k: str(v) for k, v in base_units(unit).items()})


def _unit(variable):
    """The variable's unit if it is declared (readable), else None."""
    return variable.unit if variable.unit is not None and base_units(variable.unit) else None


def _declared(interface, fmi_version):
    """The variables of a version: FMI 2.0 has no independent variable."""
    return [v for v in interface.variables if fmi_version == "3.0" or v.causality != "independent"]


def _log_categories(parent):
    categories = ET.SubElement(parent, "LogCategories")
    ET.SubElement(
        categories,
        "Category",
        name="logStatusError",
        description="A refused call: a step of another size than the sampling period, an "
        "unknown value reference, a call in the wrong state",
    )
    ET.SubElement(
        categories,
        "Category",
        name="logHeldSamples",
        description="A held sample (an input not finite, or an outlier), with debug logging on",
    )


def _variable(parent, variable, fmi_version):
    """A variable's element: in FMI 2.0 a ``ScalarVariable`` holding its type's element with
    the unit and the start value, in FMI 3.0 the type's element with all attributes."""
    common = {
        "name": variable.name,
        "valueReference": str(variable.value_reference),
        "description": variable.description,
        "causality": variable.causality,
        "variability": "discrete" if variable.causality == "output" else "continuous",
    }
    if variable.causality == "output":
        common["initial"] = "calculated"
    typed = {}
    if variable.causality == "input":
        typed["start"] = "0"
    if variable.kind == "real" and _unit(variable):
        typed["unit"] = variable.unit
    if fmi_version == "2.0":
        element = ET.SubElement(parent, "ScalarVariable", common)
        ET.SubElement(element, {"real": "Real", "integer": "Integer"}[variable.kind], typed)
    else:
        kind = {"real": "Float64", "integer": "Int32"}[variable.kind]
        ET.SubElement(parent, kind, {**common, **typed})


def _text(root):
    ET.indent(root)
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"


def model_description(interface, fmi_version, source_files):
    """Text of ``modelDescription.xml`` for FMI ``fmi_version`` ("2.0" or "3.0")."""
    common = {
        "fmiVersion": fmi_version,
        "modelName": interface.model_identifier,
        "description": interface.description,
        "generationTool": f"skhmmgmr {__version__} (skhmmgmr.export.write_fmu)",
        "variableNamingConvention": "flat",
    }
    period = _number(interface.sampling_period)
    if fmi_version == "2.0":
        root = ET.Element(
            "fmiModelDescription",
            {**common, "guid": interface.token, "numberOfEventIndicators": "0"},
        )
        cosimulation = ET.SubElement(
            root,
            "CoSimulation",
            modelIdentifier=interface.model_identifier,
            canHandleVariableCommunicationStepSize="false",
            canNotUseMemoryManagementFunctions="true",
        )
        files = ET.SubElement(cosimulation, "SourceFiles")
        for name in source_files:
            ET.SubElement(files, "File", name=name)
    else:
        root = ET.Element("fmiModelDescription", {**common, "instantiationToken": interface.token})
        ET.SubElement(
            root,
            "CoSimulation",
            modelIdentifier=interface.model_identifier,
            canHandleVariableCommunicationStepSize="false",
            fixedInternalStepSize=period,
            hasEventMode="false",
        )
    declared = _declared(interface, fmi_version)
    _unit_definitions(root, declared)
    _log_categories(root)
    ET.SubElement(root, "DefaultExperiment", startTime="0.0", stepSize=period)
    variables = ET.SubElement(root, "ModelVariables")
    for variable in declared:
        _variable(variables, variable, fmi_version)
    outputs = [v for v in declared if v.causality == "output"]
    structure = ET.SubElement(root, "ModelStructure")
    if fmi_version == "2.0":
        # FMI 2.0 names a variable by its 1-based position in ModelVariables
        index = {v.name: str(i + 1) for i, v in enumerate(declared)}
        for group in ("Outputs", "InitialUnknowns"):
            element = ET.SubElement(structure, group)
            for variable in outputs:
                ET.SubElement(element, "Unknown", index=index[variable.name], dependencies="")
    else:
        for tag in ("Output", "InitialUnknown"):
            for variable in outputs:
                ET.SubElement(
                    structure,
                    tag,
                    valueReference=str(variable.value_reference),
                    dependencies="",
                )
    return _text(root)


def build_description(interface, source_files):
    """Text of ``sources/buildDescription.xml`` (FMI 3.0): one C99 build of the sources,
    linked with the C math library."""
    root = ET.Element("fmiBuildDescription", fmiVersion="3.0")
    configuration = ET.SubElement(
        root,
        "BuildConfiguration",
        modelIdentifier=interface.model_identifier,
        description="The generated filter and its FMI 3.0 interface, standard C99 and math.h",
    )
    sources = ET.SubElement(configuration, "SourceFileSet", language="C99")
    for name in source_files:
        ET.SubElement(sources, "SourceFile", name=name)
    ET.SubElement(configuration, "Library", name="m", description="The C math library (libm)")
    return _text(root)
