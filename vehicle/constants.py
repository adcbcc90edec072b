"""Physical constants shared by the model (kept apart so every module can import them)."""

from __future__ import annotations

import math

__all__ = ["GRAVITY", "RPM_TO_RAD_S"]

#: Standard gravity, m/s². The world frame is ENU, so gravity is [0, 0, -GRAVITY].
GRAVITY = 9.81

#: Revolutions per minute → rad/s (rotor speeds in logs are often in RPM).
RPM_TO_RAD_S = 2.0 * math.pi / 60.0
