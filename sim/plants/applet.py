"""The applet plant: the real ArduPilot Rover firmware carrying returnlink's Lua applet, in the scenario's world
(``returnlink sim run SCENARIO --vehicle ardurover --policy applet``; docs/architecture.md §11.3).

The firmware flies in lockstep exactly as for its own failsafes (``sim.plants.firmware.FirmwarePlant``); the only
differences are aboard, as on an owner's flight controller: ``vehicle/applet/returnlink.lua`` lies in the
firmware's ``scripts/`` folder (its working directory's, as ``APM/scripts/`` on the SD card), and the parameters
set SCR_ENABLE 1 and the applet's own RLNK_ parameters (from the scenario's returnlink parameters: the same timeout,
regain time, displacement and time limits, speeds and trail spacing the native vehicle flies with). The defaults
file is read before the applet adds its parameter table, and ArduPilot applies a defaults file's values to a
scripted table when the script adds it, so nothing is set over MAVLink and no reboot is needed.

Backstop: the firmware's own GCS failsafe stays on (FS_GCS_ENABLE 1, FS_ACTION 2, Hold) with FS_GCS_TIMEOUT
``BACKSTOP_S``, well beyond the applet's timeout, so the applet acts first and the failsafe takes over only after
a return that has not found the link within that time, or when the applet has died.

The vehicle-side telemetry radio reports RADIO_STATUS into the firmware's port once a second as a SiK radio does
(its ``rssi`` the operator station's signal at the robot, ``link.proxy.RadioReport``), which the applet reads where
the firmware lets scripts receive MAVLink.

The applet's return is in GUIDED, the operator's own mode, so the firmware's mode timeline alone does not show it:
the record reads the applet's STATUSTEXTs from the firmware's output before any radio (``Tap.texts``, the truth),
and a return episode runs from its "return:" text, through the HOLD it ends in, until the operator takes control
again (``return_timeline``). The scripted operator is ``sim.firmware.applet_operator.AppletOperator``.
"""

from __future__ import annotations

from pathlib import Path

from link.plan_items import NAV_RETURN_TO_LINK
from link.proxy import RadioReport
from link.radio import LinkState
from sim import registry
from sim.firmware.applet_operator import AppletOperator
from sim.firmware.lockstep import MODE_NAMES, SPEEDUP, Lockstep
from sim.firmware.operator import GUIDED, RETURN_MODES
from sim.plants.firmware import FirmwarePlant, firmware_params
from sim.scenario import Scenario
from vehicle.applet import SCRIPT, TEXT_PREFIX
from vehicle.params import load_defaults
from vehicle.service import PlanItem

BACKSTOP_S = 30.0  # FS_GCS_TIMEOUT: the firmware's failsafe waits this long for the applet's return
RETURNING = 1015  # the record's own mode number for "GUIDED, driven by the applet" (no ArduPilot mode has it)
# the applet's parameters and the native ones they mirror
MIRRORED = {"RLNK_TIMEOUT": "LNK_TIMEOUT", "RLNK_REGAIN_S": "LNK_REGAIN_S", "RLNK_GOOD_S": "LNK_GOOD_S",
            "RLNK_MAX_DISP": "RTL_MAX_DISP", "RLNK_MAX_TIME": "RTL_MAX_TIME", "RLNK_SPEED": "RTL_SPEED",
            "RLNK_APPR_SPD": "RTL_APPROACH_SPD", "RLNK_ARRIVE_R": "RTL_ARRIVE_R", "RLNK_SPACING": "TRL_SPACING",
            "RLNK_TOL": "TRL_TOL"}


def applet_params(scenario: Scenario) -> dict[str, float]:
    """The applet's RLNK_ parameters for ``scenario``: the native vehicle's defaults with the scenario's own on top,
    and the first RETURN_TO_LINK item's displacement limit where the plan gives one (the native return's bound)."""
    native = load_defaults()
    for k, v in scenario.params.items():
        native.set(k, v)
    out = {}
    for name, mirror in MIRRORED.items():
        try:
            out[name] = float(native[mirror])
        except KeyError:
            continue
    for item in scenario.plan:
        if isinstance(item, PlanItem) and item.command == NAV_RETURN_TO_LINK and item.param1 > 0:
            out["RLNK_MAX_DISP"] = float(item.param1)
            break
    return out


class AppletPlant(FirmwarePlant):
    """The firmware with returnlink's Lua applet aboard (see the module docstring)."""

    policies = registry.APPLET_PLANT.policies
    mode_names = {**MODE_NAMES, RETURNING: "GUIDED (applet)"}

    def __init__(self, scenario: Scenario, kind: str = FirmwarePlant.kind, seed: int | None = None,
                 policy: str = policies[0], firmware: Path | None = None, log_path: Path | None = None,
                 speedup: float = SPEEDUP, script: Path = SCRIPT, backstop_s: float = BACKSTOP_S) -> None:
        """``script``: the Lua file to carry (the tests give a broken one to see the backstop take over);
        ``backstop_s``: the firmware's FS_GCS_TIMEOUT."""
        self._set_scene(scenario, kind, seed, policy, firmware, "firmware binary")
        self.rlnk = applet_params(scenario)
        params = {**firmware_params(policy, self.lnk_timeout, self.robot.max_speed, self.robot.max_accel),
                  "FS_GCS_TIMEOUT": backstop_s, "SCR_ENABLE": 1, **self.rlnk}
        self.link = Lockstep(self.world, self.robot, firmware, params, speedup, log_path, scripts=(Path(script),))
        self.air_radio = RadioReport()

    def _make_operator(self, sc: Scenario) -> AppletOperator:
        return AppletOperator(sc.route, sc.resume_route, self.origin, sc.attempts,
                              sysid=sc.station(sc.operator_station).sysid,
                              applet_timeout=self.rlnk.get("RLNK_TIMEOUT", self.lnk_timeout), rejoin=sc.rejoin)

    def radio_status(self, state: LinkState, t: float) -> None:
        """The vehicle-side radio's RADIO_STATUS into the firmware's port (the radio sits on the robot: no loss)."""
        if self._connected():
            self.link.send(self.air_radio.frame(state))

    # ----- the record ------------------------------------------------------------------------------------------
    @property
    def applet_texts(self) -> list[tuple[float, str]]:
        """What the applet said, when (scenario time, read before any radio)."""
        return [(t, text) for t, text in self.link.tap.texts if text.startswith(TEXT_PREFIX)]

    @property
    def return_timeline(self) -> list[tuple[float, int]]:
        """The firmware's modes with the applet's returns marked: from its "return:" text until it stops or ends,
        GUIDED reads ``RETURNING`` (a return mode of this record, so ``sim.firmware.metrics.episodes`` finds it)."""
        marks = []
        for t, text in self.applet_texts:
            words = text[len(TEXT_PREFIX):]
            if words.startswith("return:"):
                marks.append((t, "start"))
            elif words.startswith("stopped:"):
                marks.append((t, "stop"))  # it switched to HOLD just before: the return lasts until that shows
            elif words.startswith("ended:"):
                marks.append((t, "end"))  # someone else's mode or target: over at once
        events = sorted([(t, 0, m) for t, m in self.link.tap.modes] + [(t, 1, m) for t, m in marks],
                        key=lambda e: (e[0], e[1]))
        out: list[tuple[float, int]] = []
        mode, busy, stopping = None, False, False
        for t, kind, value in events:
            if kind == 0:
                mode = value
                if stopping:
                    busy = stopping = False
            elif value == "start":
                busy, stopping = True, False
            elif value == "stop":
                stopping = busy
            else:
                busy = stopping = False
            shown = RETURNING if busy and mode == GUIDED else mode
            if shown is not None and (not out or out[-1][1] != shown):
                out.append((t, shown))
        return out

    return_modes = RETURN_MODES | {RETURNING}  # what sim.firmware.metrics counts as a return
