"""Fixtures shared by the CLI tests."""

from __future__ import annotations

import pytest
from mavsysid.vehicle.config import VehicleConfig, load_vehicle

from tests.support.fake_planner import fake_result


@pytest.fixture
def planned(monkeypatch: pytest.MonkeyPatch) -> list:
    """`run_plan` replaced by a fake that records the settings it gets."""
    calls: list = []

    def run_plan(vehicle, settings, random=False, progress=True, say=None):
        calls.append(settings)
        config = vehicle if isinstance(vehicle, VehicleConfig) else load_vehicle(vehicle)
        return fake_result(config, settings, "dopt")

    monkeypatch.setattr("mavsysid.cli.plan.run_plan", run_plan)
    return calls
