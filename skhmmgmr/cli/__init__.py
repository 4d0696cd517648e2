"""Command line: ``skhmmgmr demo | select | report | fit | predict | export-c``."""

from ._commands import (
    DEMO_SCALES,
    build_parser,
    command_demo,
    command_export_c,
    command_fit,
    command_predict,
    command_report,
    command_select,
    main,
)

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
