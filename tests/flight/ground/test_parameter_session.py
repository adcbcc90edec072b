"""ParameterSession against the simulated vehicle over UDP loopback, both personalities.

The vehicle's own parameter table (``endpoint.params``) is the ground truth the session's
reads, sets and restores are checked against.
"""

from __future__ import annotations

import pytest
from mavsysid.flight.autopilot_modes import Autopilot
from mavsysid.flight.ground.parameter_session import ParameterSession

from mavsysid.errors import JobFailedError
from tests.support.sim_link import linked_sim

#: (autopilot, a float parameter, an integer parameter) of each personality.
CASES = [(Autopilot.ARDUPILOT, "GUID_TIMEOUT", "ANGLE_MAX"),
         (Autopilot.PX4, "COM_OF_LOSS_T", "COM_OBL_RC_ACT")]


@pytest.mark.parametrize(("autopilot", "real", "integer"), CASES)
def test_read_returns_the_vehicles_values_and_omits_unknown(autopilot, real, integer):
    with linked_sim(autopilot) as (endpoint, link):
        session = ParameterSession(link)
        values = session.read([real, integer, "NO_SUCH_PARAM"], timeout=2.0)
        assert values == {real: endpoint.params[real], integer: endpoint.params[integer]}


@pytest.mark.parametrize(("autopilot", "real", "integer"), CASES)
def test_set_then_restore_puts_back_every_original(autopilot, real, integer):
    with linked_sim(autopilot) as (endpoint, link):
        session = ParameterSession(link)
        original = {real: endpoint.params[real], integer: endpoint.params[integer]}
        session.set(real, 0.5)
        session.set(integer, original[integer] + 3)
        session.set(real, 0.75)  # a second change keeps the first original
        assert endpoint.params[real] == pytest.approx(0.75)
        assert endpoint.params[integer] == original[integer] + 3
        assert session.changed == {real: (pytest.approx(original[real]), 0.75),
                                   integer: (original[integer], original[integer] + 3)}
        order: list[str] = []
        endpoint.params.add_listener(lambda name, _value: order.append(name))
        assert session.restore() == []
        assert order == [integer, real]  # newest first
        assert {n: endpoint.params[n] for n in original} == pytest.approx(original)
        assert session.changed == {}
        assert set(session.restored) == {real, integer}
        assert session.restore() == []  # nothing left: harmless twice


def test_setting_the_current_value_changes_nothing():
    with linked_sim() as (endpoint, link):
        session = ParameterSession(link)
        session.set("GUID_TIMEOUT", endpoint.params["GUID_TIMEOUT"])
        assert session.changed == {}


def test_unknown_parameter_is_refused_in_one_line():
    with linked_sim() as (_endpoint, link):
        session = ParameterSession(link, set_timeout=1.0)
        with pytest.raises(JobFailedError, match="parameter NO_SUCH_PARAM: the vehicle did "
                                                 "not answer") as info:
            session.set("NO_SUCH_PARAM", 1.0)
        assert "\n" not in str(info.value)
        assert session.changed == {}


def test_a_value_the_vehicle_clamps_is_reported():
    """An int8 parameter asked for 1000 is stored clamped (127): not confirmed."""
    with linked_sim() as (endpoint, link):
        session = ParameterSession(link)
        with pytest.raises(JobFailedError, match="DISARM_DELAY: set to 1000, but the vehicle "
                                                 "keeps 127"):
            session.set("DISARM_DELAY", 1000)
        assert session.restore() == []
        assert endpoint.params["DISARM_DELAY"] == 10


def test_restore_reports_instead_of_raising_when_the_vehicle_is_gone():
    with linked_sim() as (endpoint, link):
        session = ParameterSession(link, set_timeout=1.0)
        session.set("GUID_TIMEOUT", 0.5)
        endpoint.stop()
        problems = session.restore()
        assert len(problems) == 1
        assert problems[0].startswith("could not restore GUID_TIMEOUT to 3:")
        assert "GUID_TIMEOUT" in session.changed
