"""Command line: ``skhmmgmr demo | select | report | fit | predict | export-c | export-fmu``
(``python -m skhmmgmr``).

Every sub-command lives in the module of its idea, as a ``command_*`` function run with the
parsed options and an ``add_*`` function that declares them: the framework and its report
(``demo``, ``select``, ``report``: :mod:`._framework`), ``fit`` (:mod:`._fit`), ``predict``
(:mod:`._predict`) and the exports of a model file (``export-c``, ``export-fmu``:
:mod:`._export`). This
module lists them (:data:`COMMANDS`, in the order of ``--help``), builds the parser and runs a
command.

Errors the user can fix (a missing file or column, unreadable data, an output that would
overwrite a file) are printed without a traceback and end with exit code 2, as argparse ends
on an option it refuses. Reading inputs and guarding outputs is :mod:`._files`' job.
"""

import argparse
import sys

from .._version import __version__
from ._export import add_export_c, add_export_fmu
from ._files import CommandError
from ._fit import add_fit
from ._framework import add_demo, add_report, add_select
from ._options import HelpFormatter
from ._predict import add_predict

#: The sub-commands, in the order ``skhmmgmr --help`` lists them: one ``add_*(sub, common)``
#: each, which adds its parser to ``sub`` (with the ``common`` keywords) and its handler.
COMMANDS = (
    add_demo,
    add_select,
    add_report,
    add_fit,
    add_predict,
    add_export_c,
    add_export_fmu,
)


def build_parser():
    description = "HMM-GMR driver steering-torque models."
    parser = argparse.ArgumentParser(
        "skhmmgmr", description=description, formatter_class=HelpFormatter
    )
    parser.add_argument("--version", action="version", version=f"skhmmgmr {__version__}")
    parser.add_argument("--quiet", action="store_true", help="print results only")
    sub = parser.add_subparsers(dest="command", required=True)
    quiet = argparse.ArgumentParser(add_help=False)
    # SUPPRESS keeps a --quiet given before the sub-command
    text = "print results only (default: False)"
    quiet.add_argument("--quiet", action="store_true", default=argparse.SUPPRESS, help=text)
    common = dict(parents=[quiet], formatter_class=HelpFormatter)
    for add in COMMANDS:
        add(sub, common)
    return parser


def main(argv=None):
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.handler(args)
    except CommandError as exc:
        print(f"skhmmgmr {args.command}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
