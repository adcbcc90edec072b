"""The ``mavsysid`` command line: one module per command, each only parsing, calling and printing.

`main` dispatches to the command modules; the work is done by one library function per
command in the pipeline (`mavsysid.pipeline`), except ``evaluate`` (the paper's evaluation,
`mavsysid.experiments.evaluate_job`) and ``sim`` (the simulated vehicle,
`mavsysid.flight.simvehicle`).
"""

from __future__ import annotations

from mavsysid.cli.main import build_parser, main

__all__ = ["build_parser", "main"]
