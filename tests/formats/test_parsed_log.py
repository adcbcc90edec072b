"""The autopilot-log readers' shared parts (`mavsysid.formats.parsed_log`)."""

from __future__ import annotations

import numpy as np
from mavsysid.formats.parsed_log import motor_output_count


def test_motor_output_count_ignores_idle_slots() -> None:
    rng = np.random.default_rng(3)
    moving = 1100.0 + 400.0 * rng.random((50, 4))
    servo = np.full((50, 1), 1500.0)
    unused = np.zeros((50, 9))
    assert motor_output_count(np.hstack([moving, servo, unused])) == 4
    assert motor_output_count(np.hstack([moving, moving[:, :2], unused])) == 6
    # Never armed: every motor at its disarmed PWM, unused slots at 0.
    assert motor_output_count(np.hstack([np.full((50, 6), 900.0), unused])) == 6
    # PX4 actuator_motors: NaN for an unused slot, NaN at times for a stopped motor.
    control = np.hstack([rng.random((50, 4)), np.full((50, 4), np.nan)])
    control[:10, 2] = np.nan
    assert motor_output_count(control) == 4
    assert motor_output_count(np.zeros((50, 8))) == 0
