"""Belief pruning at a vertex (paper Eq. compare), `mavsysid.planner.graph.Vertex.keep`."""

from __future__ import annotations

import numpy as np
import pytest
from mavsysid.planner.belief import identity_transfer
from mavsysid.planner.graph import Belief, Vertex
from mavsysid.planner.segments import VertexState


def _vertex() -> Vertex:
    return Vertex(VertexState.hover(np.zeros(3), 0.0), None, identity_transfer(), True)


def _belief(cost: float) -> Belief:
    return Belief(np.eye(18), cost, 0, None, None, 0.0, 0.0, 0, True)


def _keep_by_loop(kept: list[np.ndarray], key: np.ndarray) -> tuple[bool, list[np.ndarray]]:
    """The rule written out pairwise, as the paper states it."""
    if any(np.all(k <= key) for k in kept):
        return False, kept
    return True, [k for k in kept if not np.all(key <= k)] + [key]


def test_dominated_belief_is_rejected_and_nothing_changes():
    """A belief no better in cost and both log dets than a kept one is not kept."""
    v = _vertex()
    first = _belief(1.0)
    assert v.keep(first, np.array([1.0, -5.0, -3.0]))
    assert not v.keep(_belief(2.0), np.array([2.0, -5.0, -3.0]))
    assert not v.keep(_belief(1.0), np.array([1.0, -5.0, -3.0]))  # a tie is dominated
    assert v.beliefs == [first] and v.keys.shape == (1, 3)


def test_dominating_belief_prunes_the_beliefs_it_beats():
    """A belief better in every key prunes the kept ones and marks them pruned."""
    v = _vertex()
    a, b, c = _belief(2.0), _belief(1.0), _belief(0.5)
    v.keep(a, np.array([2.0, -5.0, -3.0]))
    v.keep(b, np.array([1.0, -4.0, -3.0]))  # cheaper, less informative: both stay
    assert v.beliefs == [a, b]
    assert v.keep(c, np.array([0.5, -4.5, -3.0]))  # beats b only
    assert v.beliefs == [a, c] and b.pruned and not a.pruned
    np.testing.assert_array_equal(v.keys, [[2.0, -5.0, -3.0], [0.5, -4.5, -3.0]])


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_vertex_keeps_the_same_beliefs_as_the_pairwise_rule(seed):
    """Over random key streams, the kept set equals the pairwise rule's, in order."""
    rng = np.random.default_rng(seed)
    v, reference = _vertex(), []
    for _ in range(300):
        key = rng.integers(0, 6, size=3).astype(float)  # small range: many ties
        kept, reference = _keep_by_loop(reference, key)
        assert v.keep(_belief(key[0]), key) == kept
        np.testing.assert_array_equal(v.keys, np.array(reference).reshape(-1, 3))
    assert len(v.beliefs) == len(reference)
