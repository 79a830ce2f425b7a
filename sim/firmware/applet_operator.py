"""The scripted operator of an applet run: a person flying an ArduPilot rover in GUIDED that carries returnlink's
Lua applet (``vehicle/applet/returnlink.lua``, docs/architecture.md §11.3).

It flies as ``sim.firmware.operator.FirmwareOperator`` does, and knows, as the owner who installed the applet
does, that after a silence of RLNK_TIMEOUT the rover drives itself back in GUIDED, the operator's own mode. So it
keeps its hands off a rover it finds in GUIDED after a freeze that long, or one whose applet says (STATUSTEXT
"RLNK: return: ...") it is returning, until the applet says it has stopped or ended, the rover is in HOLD (the
applet's stop, or the firmware's failsafe; then it takes control back as after any failsafe), or the rover has
stood still for ``REST_S`` in GUIDED (no applet at work). Without this, the first position report after the link
came back would bring a new GUIDED target, which the applet rightly reads as the pilot taking over: every return
would end the moment the link came back, by the operator's hand rather than by the applet's stop.
"""

from __future__ import annotations

from sim.firmware.operator import GUIDED, REST_S, REST_SPEED, FirmwareOperator
from vehicle.applet import TEXT_PREFIX

BUSY_WORDS = ("return:",)  # the applet's text when a return starts
DONE_WORDS = ("stopped:", "ended:", "no return:")  # ... when it is over (or never began)


class AppletOperator(FirmwareOperator):
    """``applet_timeout``: the applet's RLNK_TIMEOUT, which the owner set."""

    lets_go = False  # a frozen picture sends the applet nothing that could read as the pilot's

    def __init__(self, *args, applet_timeout: float = 3.0, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.applet_timeout = applet_timeout
        self.applet_busy = False
        self.still_since: float | None = None

    def _position_heard(self, t: float) -> None:
        if self.last_position_t is not None and t - self.last_position_t >= self.applet_timeout:
            self.applet_busy = True  # silent long enough for the applet to have taken over
            self._say(t, "picture back after the applet's timeout: hands off")

    def _text_heard(self, text: str, t: float) -> None:
        if not text.startswith(TEXT_PREFIX):
            return
        words = text[len(TEXT_PREFIX):]
        if words.startswith(BUSY_WORDS):
            self.applet_busy = True
        elif words.startswith(DONE_WORDS):
            self.applet_busy = False
        self._say(t, f"heard {text}")

    def _step(self, t: float) -> None:
        if self.applet_busy and self.phase in ("driving", "resuming") and self.fresh(t):
            if self.mode != GUIDED:
                self.applet_busy = False  # HOLD or a failsafe: the usual take-back follows
            else:
                self.still_since = (self.still_since if self.still_since is not None else t) \
                    if self.speed < REST_SPEED else None
                if self.still_since is not None and t - self.still_since >= REST_S:
                    self.applet_busy = False  # standing in GUIDED: nobody is returning it
                else:
                    self._lost_on_the_way()
                    self.sent_target = None
                    return
        self.still_since = None
        super()._step(t)
