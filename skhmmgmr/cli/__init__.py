"""Command line: ``skhmmgmr demo | select | report | fit | predict | export-c``."""

from ._commands import build_parser, main
from ._export import command_export_c
from ._fit import command_fit
from ._framework import DEMO_SCALES, command_demo, command_report, command_select
from ._predict import command_predict

__all__ = [
    "DEMO_SCALES",
    "build_parser",
    "command_demo",
    "command_export_c",
    "command_fit",
    "command_predict",
    "command_report",
    "command_select",
    "main",
]
