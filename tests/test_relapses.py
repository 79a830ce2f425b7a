"""``relapses``: a loss that follows a regain with nobody driving in between is the return's (it stopped where the
link would not hold); a loss after the operator drove on is the operator's."""

from __future__ import annotations

from sim.metrics import relapses
from vehicle.app import DT, State
from vehicle.lease_terms import ExpireReason, Holder, LeaseEvent


def event(t: float, reason: ExpireReason) -> LeaseEvent:
    return LeaseEvent(t, 1, 0, 1, reason, Holder.OPERATOR)


def states(seconds: float, teleop: tuple[float, float] | None = None) -> list[int]:
    """AWAITING_CLAIM throughout, TELEOP within ``teleop`` (from, to) if given."""
    out = []
    for k in range(round(seconds / DT)):
        t = k * DT
        out.append(State.TELEOP if teleop and teleop[0] <= t < teleop[1] else State.AWAITING_CLAIM)
    return out


LOST, REGAINED = ExpireReason.COMMS_LOST, ExpireReason.LINK_REGAINED


def test_a_loss_at_the_rest_point_is_a_relapse():
    log = [event(10.0, LOST), event(20.0, REGAINED), event(26.0, LOST)]
    assert relapses(log, states(40.0)) == 1


def test_a_loss_after_the_operator_drove_on_is_not():
    log = [event(10.0, LOST), event(20.0, REGAINED), event(26.0, LOST)]
    assert relapses(log, states(40.0, teleop=(22.0, 26.0))) == 0


def test_the_first_loss_and_losses_without_a_regain_are_not_relapses():
    assert relapses([event(10.0, LOST)], states(20.0)) == 0
    assert relapses([event(10.0, LOST), event(15.0, LOST)], states(20.0)) == 0
