"""The companion's stop beside ArduPilot Rover's own physics (SITL ``--model rover``), DESIGN §6.2 and issue 38: the
owner heard with full delivery within R = 18 m of home and not at all beyond, the rover driven straight out at 2 m/s
by the owner's GUIDED velocity targets until the radio loses it. The operator then lets go of the stick (a joystick at
rest still streams zero targets at 10 Hz, which the companion refuses once a return holds the lease, but hears). The
return must end where the link came back: LINK_REGAINED, the rover at rest in HOLD between R - 3 m and R from home.

Measured before the brake and the approach speed: LINK_REGAINED 2.5 m inside the edge, then HOLD rolled the rover
3.2 m further, to rest 5.7 m inside. With them (four runs): back into the range at 2.3 m/s (the firmware's speed loop
overshoots the 2.0 m/s asked for after the return's start from rest: 2.45 m/s), slowed by the firmware's own
deceleration limit, braked by zero targets: at rest 2.8-2.9 m inside (15.08, 15.19, 15.11, 15.17 m from home).
With the overshoot foreseen and taken off the targets (``vehicle.companion.governor``) the return's peak is
2.02-2.06 m/s against 2.01 driven out on that stretch, and it rests 15.31, 15.65, 15.79 m from home (2.21-2.69 m
inside; 15.52, 15.50, 15.58, 15.58 before the governor kept its foresight through a dip of a few cm/s; 15.31,
15.23, 15.51 when it never dropped its foresight, and 15.69, 15.37, 15.51 foreseeing 0.3 s ahead instead of 0.5).
What is left is the firmware's deceleration (about 1 m/s/s: some 2 m from 2 m/s) and the loop's reaction, about
0.5 s from the first packet heard to a falling speed: the rest varies with when the first owner packet falls in
the 10 Hz loops, more than the governor moves it (checked once with the governor taken out on this tree: back at
2.42 m/s, the speed check failed, at rest 15.40 m from home).
One firmware per test, on its own instance, stopped by its pid."""

from __future__ import annotations

import pytest

from tests.companion_live import firmware_companion, pump
from tests.test_companion_firmware import GUIDED, HOLD, claim_and_arm

pytestmark = pytest.mark.firmware

R = 18.0  # m: the owner's radio range (full delivery inside, none beyond)


@pytest.fixture()
def rig(tmp_path):
    """The firmware booted, the companion on its SERIAL1, and the owner's station the companion sends to."""
    with firmware_companion(tmp_path) as r:
        yield r


def test_the_companion_rests_inside_a_hard_edge_with_link_regained_beside_the_firmwares_physics(rig):
    fw, comp, owner = rig
    claim_and_arm(fw, owner)
    owner.reach = lambda: fw.distance() < R
    owner.velocity = (2.0, 0.0)
    outbound = 0.0  # the fastest the owner drove the stretch the return drives again (from R - 3 m out)

    def out_of_range() -> bool:
        nonlocal outbound
        if fw.distance() >= R - 3.0:
            outbound = max(outbound, fw.speed)
        return fw.distance() >= R + 1.0

    pump([owner, fw], 40, out_of_range, "the rover out of the radio's range")
    owner.velocity = (0.0, 0.0)  # the stick let go: zero targets, heard again once back in range
    fastest = 0.0  # the fastest the return drove, from the owner's stop beyond the edge to the stand in HOLD
    turned = False

    def stood() -> bool:
        nonlocal fastest, turned
        turned = turned or fw.speed < 0.2  # the owner's stop: what follows is the return
        if turned:
            fastest = max(fastest, fw.speed)
        return fw.mode == HOLD and fw.speed < 0.05 and fw.distance() < R

    pump([owner, fw], 60, stood, "the rover to stand in HOLD inside the range")
    pump([owner, fw], 3)
    rest = fw.distance()
    reasons = [e.reason for e in owner.gs.events]
    print(f"rest {rest:.2f} m from home, the edge at {R:g} m; fastest back {fastest:.2f} m/s, out on that stretch "
          f"{outbound:.2f} m/s; {reasons}")
    assert "LINK_REGAINED" in reasons
    # DESIGN §6.2's R - 3 m exactly (see the module docstring for the runs measured)
    assert R - 3.0 <= rest <= R, f"rests {rest:.2f} m from home, the edge at {R:g} m"
    assert fw.mode == HOLD
    # never faster back than out: the firmware's speed loop overshoots a target after a start from rest (2.45 m/s
    # for 2.0, out and back alike); the companion takes the foreseen overshoot off its targets
    assert fastest <= outbound + 0.1, f"back at {fastest:.2f} m/s, out at {outbound:.2f}"


def test_silent_from_25_m_and_heard_only_within_12_m_the_companion_seeks_back_and_holds(rig):
    """The owner heard all the way out, then, 25 m out, only within 12 m of home. The link map vouched for places
    the link no longer reaches; the return seeks on past them (LNK_MAP_SEEK's default, at RTL_APPROACH_SPD) and is
    back inside 12 m and standing in HOLD within LNK_REGAIN_S + 4 s of being heard, on the firmware's own clock
    (issue 38: it parked 18.3 m out in HOLD, with no link, for the two minutes the check allowed). Measured: in HOLD
    3.3 s after heard, at rest 9.98 m from home (then on the test's clock)."""
    fw, comp, owner = rig
    claim_and_arm(fw, owner)
    owner.velocity = (2.0, 0.0)
    pump([owner, fw], 40, lambda: fw.distance() >= 25.0, "the rover 25 m out")
    owner.reach = lambda: fw.distance() < 12.0
    owner.velocity = (0.0, 0.0)  # the stick let go; heard again only within 12 m
    pump([owner, fw], 90, lambda: fw.mode == GUIDED and fw.distance() < 12.0, "the return back inside 12 m")
    heard = fw.clock  # the firmware's own time (its LOCAL_POSITION_NED's time_boot_ms), never the test's clock
    pump([owner, fw], 30, lambda: fw.mode == HOLD and fw.speed < 0.05, "the rover to stand in HOLD")
    assert heard is not None and fw.clock is not None
    took = fw.clock - heard
    rest = fw.distance()
    reasons = [e.reason for e in owner.gs.events]
    print(f"in HOLD {took:.1f} s after heard, at rest {rest:.2f} m from home; {reasons}")
    assert "LINK_REGAINED" in reasons
    assert rest < 12.0 and took <= 1.0 + 4.0, f"in HOLD {took:.1f} s after heard, {rest:.2f} m from home"
