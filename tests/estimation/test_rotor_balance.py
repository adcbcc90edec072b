"""Rotor speeds that contradict a vehicle holding its attitude are refused in one line."""

from __future__ import annotations

import numpy as np
import pytest
from mavsysid.estimation.checks import (
    check_rotor_balance,
    rescale_wrong_rotor,
    thrust_centroid_offset,
)
from mavsysid.estimation.flight import FlightData
from mavsysid.vehicle.config import load_vehicle

from mavsysid.errors import JobFailedError

CONFIG = load_vehicle("micro_quad")


def _flight(scale: np.ndarray, seed: int = 0) -> FlightData:
    rng = np.random.default_rng(seed)
    n = 1900.0 * (1.0 + 0.03 * rng.standard_normal((2000, 4))) * scale
    t = np.arange(2000) * 0.002
    return FlightData(t, np.zeros((2000, 3)), np.tile([1.0, 0, 0, 0], (2000, 1)), n, "f.csv")


@pytest.mark.parametrize("trim", [[1.0, 1.0, 1.0, 1.0], [1.03, 0.97, 1.02, 0.98]])
def test_balanced_rotors_pass(trim):
    """A few per cent of trim between rotors is a balanced vehicle."""
    flight = _flight(np.array(trim))
    assert np.hypot(*thrust_centroid_offset(flight.rotor_speeds, CONFIG)) < 0.1
    check_rotor_balance(flight, CONFIG)


@pytest.mark.parametrize("rotor", [0, 2])
def test_a_rotor_reading_half_its_speed_is_refused_naming_it(rotor):
    """One rotor reading half the others' speed: exit-3 refusal naming that rotor."""
    scale = np.ones(4)
    scale[rotor] = 0.5
    with pytest.raises(JobFailedError, match=rf"^f\.csv: .*rotor {rotor + 1}'s median speed is 50 %"
                       ) as info:
        check_rotor_balance(_flight(scale), CONFIG)
    assert "\n" not in str(info.value)


@pytest.mark.parametrize(("rotor", "share"), [(0, 0.5), (3, 0.4)])
def test_a_rotor_reading_a_constant_share_is_rescaled_and_said(rotor, share):
    """One rotor reading a constant share: scaled back within 3 %, a note naming it; the
    flight then passes the balance check."""
    scale = np.ones(4)
    scale[rotor] = share
    flight = _flight(scale)
    corrected, note = rescale_wrong_rotor(flight, CONFIG)
    ratio = corrected.rotor_speeds[:, rotor] / flight.rotor_speeds[:, rotor]
    assert abs(ratio[0] * share - 1.0) < 0.03
    np.testing.assert_array_equal(np.delete(corrected.rotor_speeds, rotor, axis=1),
                                  np.delete(flight.rotor_speeds, rotor, axis=1))
    assert note is not None and f"rotor {rotor + 1}'s" in note and note in corrected.warnings
    check_rotor_balance(corrected, CONFIG)


def test_balanced_rotors_are_not_rescaled():
    """A balanced flight comes back unchanged, without a note."""
    flight = _flight(np.array([1.03, 0.97, 1.02, 0.98]))
    corrected, note = rescale_wrong_rotor(flight, CONFIG)
    assert corrected is flight and note is None


def test_two_wrong_rotors_are_not_rescaled():
    """Two rotors reading wrong on one side: no single scale balances them; left to refusal."""
    corrected, note = rescale_wrong_rotor(_flight(np.array([0.3, 0.3, 1.0, 1.0])), CONFIG)
    assert note is None
    with pytest.raises(JobFailedError):
        check_rotor_balance(corrected, CONFIG)
