"""returnlink companion beside the real ArduPilot Rover firmware in a scenario's world (docs/architecture.md §10,
§11): `sim run --vehicle ardurover --policy companion` in the tunnel, its metrics from the companion's own lease
events, its repeatability, and the policy in sweep specs. Firmware instances from 50 up."""

from __future__ import annotations

import contextlib
import io
import json
import math
import os
from pathlib import Path

import pytest

from gcs.station import mav
from link.linkmap_format import decode
from sim import metrics
from sim.campaign.spec import SpecError, load_spec, parse_spec
from sim.cli import main
from sim.compare import differing
from sim.firmware.companion_operator import CompanionOperator
from sim.firmware.metrics import REPEATABILITY
from sim.firmware.process import INSTANCE_ENV, MAX_INSTANCE, FirmwareError, claim_instance
from sim.firmware_runs import CompanionRun, FirmwareRun
from sim.plants.companion import CompanionPlant
from sim.plants.firmware import FirmwarePlant, firmware_params
from sim.policies import flies
from sim.runner import Run
from sim.scenario import load
from tests.firmware_helpers import firmware_or_skip, short_scenario
from vehicle.companion.setup import check
from vehicle.companion.setup import differing as needs_differing

pytestmark = pytest.mark.firmware

ROOT = Path(__file__).resolve().parents[1]
# s: the tunnel's link dies near 44 s, the return brings it back near 53 s and the operator takes over at 54 s and
# drives home from the bend, where the return left the rover beside the wall: until the operator kept the rover on
# its way (sim/firmware/operator.py ``_aim``) that drive scraped the adit's wall, so the run goes on past it
DURATION = 75.0


@pytest.fixture(scope="module")
def firmware() -> Path:
    return firmware_or_skip()


@pytest.fixture(scope="module")
def instance_range():
    old = os.environ.get(INSTANCE_ENV)
    os.environ[INSTANCE_ENV] = "50"
    yield
    if old is None:
        os.environ.pop(INSTANCE_ENV, None)
    else:
        os.environ[INSTANCE_ENV] = old


@pytest.fixture(scope="module")
def cli_run(firmware, instance_range, tmp_path_factory):
    """The tunnel cut short, flown by `sim run --vehicle ardurover --policy companion`: (exit code, output, dir)."""
    tmp = tmp_path_factory.mktemp("companion")
    scenario = short_scenario(tmp, duration=DURATION)
    out = tmp / "run"
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        rc = main(["sim", "run", str(scenario), "--vehicle", "ardurover", "--policy", "companion", "--firmware",
                   str(firmware), "--out", str(out), "--quiet"])
    return rc, buf.getvalue(), out


def test_the_companion_regains_the_link_by_its_return_and_rests_near_the_loss(cli_run):
    rc, text, out = cli_run
    assert rc == 0, text
    for f in ("metrics.json", "run.tlog", "trajectory.png", "timeline.png", "firmware.log"):
        assert (out / f).stat().st_size > 0, f
    m = json.loads((out / "metrics.json").read_text())
    assert m["vehicle"] == "ardurover" and m["policy"] == "companion" and m["firmware"].startswith("ArduRover V")
    assert m["passed"], m["failures"]
    assert m["collisions"] == 0
    # the loss deep in the adit, the return from the companion's own LEASE_EVENTs, within a tick of LNK_TIMEOUT
    assert m["loss_position"][0] > 30
    reasons = [e["reason"] for e in m["lease_events"]]
    assert reasons[1:3] == ["COMMS_LOST", "LINK_REGAINED"]
    lost_event = next(e for e in m["lease_events"] if e["reason"] == "COMMS_LOST")
    assert m["return_started_s"] == pytest.approx(lost_event["t"], abs=0.03)
    assert 0.0 <= m["reaction_latency_s"] <= 0.05
    assert m["regained_by"] == "return" and m["link_regained_s"] > m["return_started_s"]
    assert m["blocks"][0]["reason"] == "LINK_REGAINED" and m["blocks"][0]["command"] == "RETURN_TO_LINK"
    # it backed out to where the station is heard again: near the loss point, not home at (-5, 0)
    assert 0.5 < m["distance_back_m"] < 15
    assert math.dist(m["rest_position"], m["loss_position"]) < 6.0
    assert math.dist(m["rest_position"], (-5.0, 0.0)) > 30
    assert m["trail_points"] > 5 and m["trail_max_deviation_m"] is not None
    assert m["stale_commands_executed"] == 0 and m["estimator_rmse_m"] < 1.0
    # the firmware drove the return in GUIDED; when the link came back the companion braked it there with zero
    # targets, then HOLD, unless the operator had claimed and driven it on first (its targets end the brake,
    # vehicle/companion/app.py: the operator streams its stick at 10 Hz from the claim on, as the native one does)
    modes = [(e["t"], e["mode"]) for e in m["firmware_modes"]]
    assert [name for _t, name in modes][:2] == ["MANUAL", "GUIDED"]
    assert {name for t, name in modes if t >= m["link_regained_s"] - 0.1} <= {"GUIDED", "HOLD"}
    assert "SMART_RTL" not in [name for _t, name in modes]  # the firmware's own failsafe never fired
    assert "the companion forwarded" in text and "firmware modes:" in text


def test_the_companions_link_map_carries_the_radios_rssi(cli_run):
    """The vehicle-side radio's RADIO_STATUS reaches the companion once a second (docs/architecture.md §11.1), so
    its linkmap.csv has the owner's RSSI beside the delivery in most cells, in the autopilot's local frame."""
    rc, text, out = cli_run
    cells = decode((out / "linkmap.csv").read_bytes())
    assert len(cells) > 10
    with_rssi = [c for c in cells if math.isfinite(c.rssi_dbm)]
    assert len(with_rssi) > 0.5 * len(cells), f"{len(with_rssi)} of {len(cells)} cells have rssi_dbm"
    assert all(-127.0 <= c.rssi_dbm <= 7.0 for c in with_rssi)
    # the local frame starts at the scenario's start: the adit runs north from about 0, the run reaches 30+ m in
    assert min(c.north for c in cells) < 3.0 and max(c.north for c in cells) > 30.0


@pytest.fixture(scope="module")
def twice(firmware, instance_range):
    """The same trial flown twice in this process, for repeatability."""
    sc = load("tunnel")
    runs = []
    for _ in range(2):
        run = CompanionRun(sc, 1, firmware=firmware, duration=DURATION).run()
        run.metrics = metrics.compute(run)
        runs.append(run)
    return runs


# what follows the first return is not the firmware's to repeat: since the regain window and the approach speed
# (issue 38) the operator drives back into the adit after its claim and the link is lost again, 2 or 3 times in
# 75 s as the firmware's own timing falls (measured: the episode lists differed between two runs, every other metric
# agreed), so the lists are compared up to the first return's end
EPISODES = {"blocks", "firmware_modes", "lease_events"}


def test_same_seed_gives_the_same_metrics_within_the_firmwares_repeatability(twice):
    a, b = (r.metrics for r in twice)
    assert [k for k in differing(a, b, REPEATABILITY) if k not in EPISODES] == []
    first = [[e["reason"] for e in m["lease_events"]][:3] for m in (a, b)]
    assert first[0] == first[1] and first[0][:2] == ["NONE", "COMMS_LOST"]
    assert [(blk["command"], blk["reason"]) for blk in a["blocks"][:1]] == \
        [(blk["command"], blk["reason"]) for blk in b["blocks"][:1]]
    assert [m["mode"] for m in a["firmware_modes"][:3]] == [m["mode"] for m in b["firmware_modes"][:3]]
    assert not any(r.link.process.alive() for r in twice)


def test_the_companion_flies_its_operator_through_the_lease(twice):
    run = twice[0]
    texts = [text for _t, text in run.operator.log]
    assert texts[0].startswith("in control, epoch") and texts[1] == "plan upload accepted"
    assert any(text.startswith("claiming [") for text in texts)  # the fresh lease after the return
    assert run.forwarded > 10 and run.audit_stale == 0
    c = run.companion
    assert c.counters["forwarded"] == run.forwarded and c.driver.keepalives >= DURATION - 1


def test_the_companions_firmware_parameters_pass_its_own_check():
    params = firmware_params("companion", 3.0, 2.0)
    assert needs_differing(check(params)) == []
    assert params["FS_GCS_ENABLE"] == 1 and params["FS_ACTION"] == 2 and params["FS_THR_ENABLE"] == 0
    assert firmware_params("companion", 8.0, 2.0)["FS_GCS_TIMEOUT"] == 5.0  # the check's upper bound
    assert "MAV_OPTIONS" not in firmware_params("ardupilot-hold", 3.0, 2.0)


def test_a_spec_with_the_companion_validates_and_pairs_it_with_the_firmware():
    spec = load_spec(str(ROOT / "sim" / "campaign" / "specs" / "companion.toml"))
    pairs = {(t.vehicle, t.policy) for t in spec.trials}
    assert pairs == {("rover", "returnlink"), ("ardurover", "companion"), ("ardurover", "ardupilot-smartrtl")}
    assert len(spec.trials) == 5 * 20 * 3
    assert flies("companion", "ardurover") and not flies("companion", "rover")
    with pytest.raises(SpecError) as e:
        parse_spec('scenarios = ["tunnel"]\nvehicles = ["rover"]\npolicies = ["companion"]\n', "s.toml")
    assert e.value.field == "policies[0]" and e.value.line is not None


def test_the_companion_policy_needs_the_firmware_vehicle(tmp_path, capsys):
    with pytest.raises(SystemExit) as e:
        main(["sim", "run", "tunnel", "--out", str(tmp_path / "o"), "--policy", "companion"])
    assert e.value.code == 2 and "use --vehicle ardurover" in capsys.readouterr().err


class StubbornOperator(CompanionOperator):
    """An operator who keeps sending GUIDED targets whatever the lease says (and uploads no plan)."""

    def _follow_lease(self, t: float, st) -> None:
        super()._follow_lease(t, st)
        if st.state != mav.RETURNLINK_STATE_TELEOP:
            self._step(t)


class StubbornPlant(CompanionPlant):
    def _make_operator(self, sc):
        return StubbornOperator(sc.route, sc.resume_route, self.origin, [], sc.attempts)


class StubbornRun(CompanionRun):
    plant_type = StubbornPlant


def test_commands_sent_during_the_return_are_refused_never_forwarded(firmware, instance_range):
    """The router's authority in the world: what the operator sends while the return holds the lease never reaches
    the firmware (the run's own audit of every forwarded frame finds none), and the return still brings the link
    back."""
    run = StubbornRun(load("tunnel"), 1, firmware=firmware, duration=DURATION).run()
    m = metrics.compute(run)
    assert run.audit_stale == 0 and m["stale_commands_executed"] == 0
    # since the operator drives the native steering the return lasted 3 s here, its stream through a fading link:
    # 11 refused (more than 20 when the return was longer)
    assert m["commands_rejected"] > 5 and run.companion.counters["refused"] > 5
    assert m["regained_by"] == "return" and m["blocks"][0]["reason"] == "LINK_REGAINED"


def test_each_plant_flies_only_its_own_policies(firmware):
    sc = load("tunnel")
    with pytest.raises(ValueError, match="companion"):
        FirmwareRun(sc, 1, "companion", firmware)  # the firmware alone has no companion to fly it with
    with pytest.raises(ValueError, match="ardupilot-hold"):
        CompanionRun(sc, 1, "ardupilot-hold", firmware)
    # the one loop picks the plant from the vehicle and the policy
    assert type(Run(sc, "ardurover", 1, policy="companion", firmware=firmware).plant) is CompanionPlant
    assert type(Run(sc, "ardurover", 1, policy="ardupilot-hold", firmware=firmware).plant) is FirmwarePlant


def test_the_instance_variable_says_where_the_search_starts(monkeypatch):
    monkeypatch.setenv(INSTANCE_ENV, "57")
    n, sock = claim_instance()
    sock.close()
    assert 57 <= n <= MAX_INSTANCE
    monkeypatch.setenv(INSTANCE_ENV, "forty")
    with pytest.raises(FirmwareError, match=INSTANCE_ENV):
        claim_instance()
