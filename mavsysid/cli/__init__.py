"""The ``mavsysid`` command line: one module per command, each only parsing, calling and printing.

`main` dispatches to the command modules; the work is done by library functions in the stage
packages (`mavsysid.planner`, `mavsysid.flight`, `mavsysid.estimation`,
`mavsysid.discrepancy`) and the experiments (`mavsysid.experiments`).
"""

from __future__ import annotations

from mavsysid.cli.main import build_parser, main

__all__ = ["build_parser", "main"]
