"""The exports of a model file: ``skhmmgmr export-c``, the C code of its causal filter.

An export command reads a model file written by ``fit`` (the portable JSON, never unpickled),
checks every option and the files it will write before it makes anything (the package's rule
for output files: a missing folder is made, an existing file is replaced only with
``--overwrite``, an input never), then writes them; a refused model leaves no folder behind.
A new export (another target format) is one more ``command_*`` function and its ``add_*``
parser here, and one more line in the list of commands (``_commands.COMMANDS``).
"""

from pathlib import Path

from ._files import CommandError, check_output, load_model
from ._options import log


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
