"""Yaw branches: a vertex's yaw ψ and ψ + 2πk are the same physical state (flatness and
control read only cos ψ and sin ψ), but not the same polynomial boundary condition. These
helpers pick the branch a segment should end on, and shift segments and vertices by
whole turns so that a flight's yaw is continuous."""

from __future__ import annotations

import numpy as np
from mavsysid.planner.segments import Segment, VertexState
from mavsysid.vehicle.rotation import wrap_angle

__all__ = ["nearest_yaw_branch", "shift_segment_yaw", "shift_vertex_yaw"]


def nearest_yaw_branch(state: VertexState, yaw: float) -> VertexState:
    """The same vertex with its yaw shifted by 2πk to lie within π of ``yaw``.

    Flatness and control use only cos ψ and sin ψ, so the shifted state is the same
    physical state, and a segment to it turns the short way round.
    """
    shift = yaw + wrap_angle(float(state.yaw[0]) - yaw) - float(state.yaw[0])
    if shift == 0.0:
        return state
    return VertexState(state.position, state.yaw + np.array([shift, 0.0, 0.0]))


def _whole_turns(angle: float) -> float:
    """``angle`` rounded to a multiple of 2π (it is one up to rounding), rad."""
    return 2.0 * np.pi * round(angle / (2.0 * np.pi))


def shift_segment_yaw(segment: Segment, shift: float) -> Segment:
    """The same segment with its yaw shifted by the whole turns nearest ``shift`` (rad)."""
    turns = _whole_turns(shift)
    if turns == 0.0:
        return segment
    yaw = segment.yaw_coeffs.copy()
    yaw[0] += turns
    return Segment(segment.duration, segment.position_coeffs, yaw)


def shift_vertex_yaw(state: VertexState, shift: float) -> VertexState:
    """The same vertex with its yaw shifted by the whole turns nearest ``shift`` (rad)."""
    turns = _whole_turns(shift)
    if turns == 0.0:
        return state
    return VertexState(state.position, state.yaw + np.array([turns, 0.0, 0.0]))
