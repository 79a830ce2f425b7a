"""returnlink's Lua applet aboard the real ArduPilot Rover firmware (docs/architecture.md §11.3): the script parses
(before any firmware starts), loads, returns and stops where the link came back in the tunnel, gives way at once to
the pilot's mode change, and a script that errors leaves the firmware's own GCS failsafe in charge. One firmware per
test, each from its own instance number (120-123, which no other test file starts from)."""

from __future__ import annotations

import math
import os
import shutil
import subprocess
from pathlib import Path

import pytest
from pymavlink.dialects.v20 import ardupilotmega as apm

from sim import outputs
from sim.firmware.operator import GUIDED, HOLD
from sim.firmware.process import INSTANCE_ENV, wait_for
from sim.plants.applet import RETURNING, AppletPlant
from sim.runner import Run
from sim.scenario import load
from tests.firmware_helpers import firmware_or_skip
from vehicle.applet import SCRIPT, TEXT_PREFIX

pytestmark = pytest.mark.firmware

LUAC = "luac5.3"  # ArduPilot's scripting is Lua 5.3: Debian's compiler of that version checks the same grammar
MANUAL = 0
# s of the tunnel: the link dies near 46 s, the applet's return brings it back near 55 s
TUNNEL_S = 66.0


def luac_check(path: Path) -> subprocess.CompletedProcess:
    """``luac5.3 -p``: parse only, no output file. Missing: the set-up (make venv) did not run, a failure."""
    exe = shutil.which(LUAC)
    if exe is None:
        pytest.fail(f"{LUAC} not found: `make venv` installs Debian's lua5.3 package (apt-get install lua5.3)")
    return subprocess.run([exe, "-p", str(path)], capture_output=True, text=True, check=False)


@pytest.fixture(scope="module")
def script() -> Path:
    """The applet, parsed before any firmware starts: every firmware test here fails on a script that does not."""
    done = luac_check(SCRIPT)
    assert done.returncode == 0, done.stderr
    return SCRIPT


@pytest.fixture(scope="module")
def firmware() -> Path:
    return firmware_or_skip()


@pytest.fixture
def instance(request):
    """Each test its own instance number."""
    old = os.environ.get(INSTANCE_ENV)
    os.environ[INSTANCE_ENV] = str(request.param)
    yield request.param
    if old is None:
        os.environ.pop(INSTANCE_ENV, None)
    else:
        os.environ[INSTANCE_ENV] = old


def fly(firmware: Path, script: Path, duration: float, plant=AppletPlant, **options) -> Run:
    """The tunnel flown by the firmware carrying ``script``; its process is gone when this returns."""
    run = Run(load("tunnel"), "ardurover", None, False, duration, "applet", plant=plant, firmware=firmware,
              script=script, **options)
    try:
        run.run()
        run.metrics = outputs.compute(run)
    finally:
        proc = run.plant.link.process
        assert proc is None or proc.proc is None or wait_for(proc.proc.pid, 5.0)
    return run


def applet_texts(run: Run) -> list[tuple[float, str]]:
    return run.plant.applet_texts


def lua_errors(run: Run) -> list[str]:
    return [text for _t, text in run.plant.link.tap.texts if text.startswith("Lua") or "rror" in text]


def test_lua_that_does_not_parse_fails_the_check(tmp_path):
    broken = tmp_path / "broken.lua"
    broken.write_text(SCRIPT.read_text().replace("local function say(", "local function say(severity text", 1))
    assert luac_check(broken).returncode != 0
    assert luac_check(SCRIPT).returncode == 0


@pytest.mark.parametrize("instance", [120], indirect=True)
def test_the_script_loads_without_error(firmware, script, instance):
    run = fly(firmware, script, 5.0)
    texts = [text for _t, text in applet_texts(run)]
    assert any(text.startswith(f"{TEXT_PREFIX}ready") for text in texts), run.plant.link.tap.texts[-20:]
    assert lua_errors(run) == []


@pytest.mark.parametrize("instance", [121], indirect=True)
def test_it_returns_and_stops_where_the_link_came_back_in_the_tunnel(firmware, script, instance):
    run = fly(firmware, script, TUNNEL_S)
    m = run.metrics
    texts = applet_texts(run)
    starts = [t for t, text in texts if text.startswith(f"{TEXT_PREFIX}return:")]
    stops = [(t, text) for t, text in texts if text.startswith(f"{TEXT_PREFIX}stopped:")]
    assert len(starts) == 1 and stops and "link regained" in stops[0][1], texts
    # the record's loss is the last frame of any kind the firmware heard from the operator; the applet (like the
    # firmware's own failsafe) counts heartbeats, sent once a second: its start is up to a second "early" by that
    assert m["link_lost_s"] is not None and -1.0 - 1e-9 <= m["reaction_latency_s"] < 0.5
    assert m["regained_by"] == "return" and m["link_regained_s"] <= stops[0][0] + 0.2
    assert m["distance_back_m"] > 2.0 and m["collisions_during_return"] == 0
    # at rest in HOLD near where the link came back: no farther back than the regain and the brake take
    hold = [t for t, mode in run.plant.link.tap.modes if mode == HOLD]
    assert hold and stops[0][0] - 0.5 <= hold[0] <= stops[0][0] + 0.5
    regain_at = run.true_at(m["link_regained_s"])
    assert math.dist(regain_at, m["rest_position"]) < 1.5
    assert lua_errors(run) == []


class PilotPlant(AppletPlant):
    """The pilot switches to MANUAL (a mode switch that reaches the firmware whatever the ground link does, as a
    transmitter's would) ``AFTER_S`` into the applet's return."""

    AFTER_S = 2.0

    def tick(self, t: float) -> None:
        super().tick(t)
        starts = [s for s, text in self.applet_texts if text.startswith(f"{TEXT_PREFIX}return:")]
        if starts and not getattr(self, "switched", None) and t >= starts[0] + self.AFTER_S and self._connected():
            mav = apm.MAVLink(None, srcSystem=255, srcComponent=190)
            self.link.send(apm.MAVLink_command_long_message(1, 1, apm.MAV_CMD_DO_SET_MODE, 0,
                                                            apm.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, MANUAL,
                                                            0, 0, 0, 0, 0).pack(mav))
            self.switched = t


@pytest.mark.parametrize("instance", [122], indirect=True)
def test_the_pilots_mode_change_ends_the_return_at_once_and_is_never_fought(firmware, script, instance):
    run = fly(firmware, script, TUNNEL_S, plant=PilotPlant)
    switched = run.plant.switched
    texts = applet_texts(run)
    ended = [(t, text) for t, text in texts if text.startswith(f"{TEXT_PREFIX}ended: mode {MANUAL}")]
    assert ended and switched <= ended[0][0] <= switched + 0.5, texts
    after = [mode for t, mode in run.plant.link.tap.modes if t > switched]
    assert after and set(after) == {MANUAL}  # never switched back to GUIDED by the applet
    assert not [t for t, text in texts if t > switched and text.startswith(f"{TEXT_PREFIX}return:")]
    assert [mode for _t, mode in run.plant.return_timeline if mode == RETURNING]


@pytest.mark.parametrize("instance", [123], indirect=True)
def test_a_script_error_leaves_the_firmwares_failsafe_in_charge(firmware, script, instance, tmp_path):
    broken = tmp_path / "returnlink.lua"
    text = script.read_text()
    assert "  start_return(now, n, e)\n" in text
    broken.write_text(text.replace("  start_return(now, n, e)\n", '  error("injected fault")\n', 1))
    assert luac_check(broken).returncode == 0  # it parses; it fails only when the link is lost
    backstop = 5.0
    run = fly(firmware, broken, 60.0, backstop_s=backstop)
    texts = run.plant.link.tap.texts
    assert any("injected fault" in t for _s, t in texts), texts[-10:]
    assert not [t for t, s in applet_texts(run) if s.startswith(f"{TEXT_PREFIX}return:")]
    lost = run.metrics["link_lost_s"]
    holds = [t for t, mode in run.plant.link.tap.modes if mode == HOLD]
    assert lost is not None and holds, run.plant.link.tap.modes
    # the firmware's GCS failsafe: FS_GCS_TIMEOUT then FS_TIMEOUT (1.5 s), at its 10 Hz check and 1 Hz heartbeat;
    # the loss is the last frame heard, which the operator's 10 Hz stick stream can put up to 1 s after the last
    # heartbeat the failsafe counts
    assert backstop + 1.5 - 1.5 <= holds[0] - lost <= backstop + 1.5 + 2.0
    assert any("Failsafe" in s for _t, s in texts)
    assert [mode for t, mode in run.plant.link.tap.modes if t < holds[0]][-1] == GUIDED
