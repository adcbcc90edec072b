"""Physical constants shared by the model (kept apart so every module can import them)."""

from __future__ import annotations

__all__ = ["GRAVITY"]

#: Standard gravity, m/s². The world frame is ENU, so gravity is [0, 0, -GRAVITY].
GRAVITY = 9.81
