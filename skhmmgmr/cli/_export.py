"""The exports of a model file: ``skhmmgmr export-c``, the C code of its causal filter, and
``skhmmgmr export-fmu``, the model as a co-simulation Functional Mock-up Unit.

An export command reads a model file written by ``fit`` (the portable JSON, never unpickled),
checks every option and the files it will write before it makes anything (the package's rule
for output files: a missing folder is made, an existing file is replaced only with
``--overwrite``, an input never), then writes them; a refused model leaves no folder behind.
A new export (another target format) is one more ``command_*`` function and its ``add_*``
parser here, and one more line in the list of commands (``_commands.COMMANDS``).
"""

from pathlib import Path

from ._files import CommandError, check_output, load_model
from ._options import finite_float, log


def _checked_files(args, folder, file_names, *, option):
    """The files of an export in ``folder``, checked before anything is made (the folder
    itself: an existing path that is not a folder is refused, a missing one will be made)."""
    if folder.exists() and not folder.is_dir():
        raise CommandError(f"directory {folder} exists and is not a folder")
    paths = [folder / name for name in file_names]
    check_output(
        paths, option=option, overwrite=args.overwrite, inputs=[args.model], create_folders=True
    )
    return paths


def _missing_folders(folder):
    """The folders of ``folder``'s path that do not exist yet, innermost first."""
    missing = []
    while not folder.exists() and folder != folder.parent:
        missing.append(folder)
        folder = folder.parent
    return missing


def command_export_c(args):
    """The C code of a model file written by ``fit`` (:func:`skhmmgmr.export.write_c`)."""
    from ..export import write_c
    from ..export._model import check_name

    model = load_model(args.model)
    try:
        name = check_name(args.name)
    except ValueError as exc:
        raise CommandError(f"--name: {exc}") from exc
    folder = Path(args.directory)
    _checked_files(args, folder, [f"{name}.h", f"{name}.c"], option=f"--name {name}:")
    made = _missing_folders(folder)
    try:
        header, source = write_c(
            model, folder, name=name, dtype=args.dtype, overwrite=args.overwrite
        )
    except (ValueError, OSError) as exc:
        for empty in made:  # a refused model leaves nothing behind
            try:
                empty.rmdir()
            except OSError:
                break
        if isinstance(exc, OSError):
            raise CommandError(f"cannot write to {folder}: {exc.strerror or exc}") from exc
        raise CommandError(f"{args.model}: {exc}") from exc
    log(args, f"Wrote {header} and {source} ({args.dtype})")
    return 0


def add_export_c(sub, common):
    """The ``export-c`` sub-command and its options."""
    export = sub.add_parser(
        "export-c",
        help="write a model's causal filter as C99 source (<name>.h, <name>.c)",
        description="Write the causal filter of a model file as C99 code for embedded targets: "
        "static parameters, a caller-owned state, no heap; see the user guide, 'C code of a "
        "fitted model'.",
        **common,
    )
    export.add_argument("model", help="model file (portable JSON) written by 'skhmmgmr fit'")
    export.add_argument("directory", help="folder the two files are written to (made if absent)")
    export.add_argument("--name", default="skhmmgmr_model", help="C prefix of files and names")
    export.add_argument(
        "--float32",
        dest="dtype",
        action="store_const",
        const="float32",
        default="float64",
        help="single-precision arithmetic (default: double)",
    )
    export.add_argument(
        "--overwrite", action="store_true", help="replace existing files of that name"
    )
    export.set_defaults(handler=command_export_c)
    return export


def command_export_fmu(args):
    """The FMU of a model file written by ``fit`` (:func:`skhmmgmr.export.write_fmu`), with the
    file's output names, units and sampling period."""
    import json

    from ..export import write_fmu

    model, training = load_model(args.model, return_training=True)
    path = Path(args.path)
    if path.exists() and not args.overwrite:
        raise CommandError(f"PATH {path} exists; pass --overwrite to replace it")
    check_output(path, option="PATH", overwrite=True, inputs=[args.model], create_folders=True)
    data = json.loads(Path(args.model).read_text(encoding="utf-8"))  # valid: load read it
    regressor = data["steps"][-1]["model"] if "steps" in data else data
    period = args.sampling_period
    if period is None:
        period = training.get("sampling_period")
    try:
        written = write_fmu(
            model,
            path,
            fmi_version=args.fmi_version,
            name=args.name,
            sampling_period=period,
            output_names=regressor["output_names"],
            units=training.get("units"),
            binary=not args.sources_only,
            overwrite=args.overwrite,
        )
    except ValueError as exc:
        raise CommandError(f"{args.model}: {exc}") from exc
    except (ImportError, RuntimeError) as exc:
        raise CommandError(str(exc)) from exc
    except OSError as exc:
        raise CommandError(f"cannot write {path}: {exc.strerror or exc}") from exc
    what = "sources only" if args.sources_only else "sources and a binary for this platform"
    log(args, f"Wrote {written} (FMI {args.fmi_version}, {what})")
    return 0


def add_export_fmu(sub, common):
    """The ``export-fmu`` sub-command and its options."""
    fmu = sub.add_parser(
        "export-fmu",
        help="write a model as a co-simulation Functional Mock-up Unit (.fmu)",
        description="Write a model file as a co-simulation FMU (FMI 2.0 or 3.0) for vehicle "
        "simulators: the model's C filter, its FMI wrapper and a binary for this platform "
        "built with the system C compiler (cc) against FMPy's FMI headers (pip install "
        "'skhmmgmr[fmu]'); see the user guide, 'Using the model in a vehicle simulator'.",
        **common,
    )
    fmu.add_argument("model", help="model file (portable JSON) written by 'skhmmgmr fit'")
    fmu.add_argument("path", help="the .fmu file to write (its folder made if absent)")
    fmu.add_argument("--fmi-version", choices=("2.0", "3.0"), default="2.0", help="FMI version")
    fmu.add_argument(
        "--name", help="model identifier: C prefix and binary name (default: the file's stem)"
    )
    fmu.add_argument(
        "--sampling-period",
        type=finite_float,
        help="seconds between two samples, the FMU's communication step (default: the model "
        "file's)",
    )
    fmu.add_argument(
        "--sources-only",
        action="store_true",
        help="no binary: an FMU of sources the importer builds (needs no compiler)",
    )
    fmu.add_argument("--overwrite", action="store_true", help="replace an existing file")
    fmu.set_defaults(handler=command_export_fmu)
    return fmu
