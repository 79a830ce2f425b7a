"""``returnlink gcs map``: a live map of the robot in the browser, served on 127.0.0.1 by the ground station itself.

The page (``gcs/web/``: static HTML, JavaScript and SVG, no build step, nothing from the internet) polls ``/state``
for a JSON snapshot and posts lease actions to ``/action/NAME``. Everything it shows reaches the station over
MAVLink: position from LOCAL_POSITION_NED (the station's own track, ``gcs/track.py``, coloured by the share of
reports it heard), lease sequence, state, return start and target and displacement from LEASE_STATUS, events from
LEASE_EVENT, the return plan by the standard mission download; the link layer from the vehicle's link map
(``linkmap.csv`` bytes from a ``LinkMapSource``). The station is the same long-lived ``Session`` the
shell uses, so the link (and the operator's heartbeat) lives as long as the page is served.
"""

from __future__ import annotations

import json
import math
import sys
import threading
from http import HTTPStatus
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from typing import TextIO

from gcs.client import Client, GcsError
from gcs.linkmap_layer import LinkMapSource, layer
from gcs.plans import describe
from gcs.shell import Session
from gcs.track import Track, return_route

WEB = Path(__file__).with_name("web")
STATIC = {"/": ("index.html", "text/html; charset=utf-8"), "/map.js": ("map.js", "text/javascript; charset=utf-8"),
          "/map.css": ("map.css", "text/css; charset=utf-8")}
ACTIONS = ("acquire", "rtl", "hold", "claim")


def _num(x: float | None) -> float | None:
    """JSON has no NaN: unknown numbers travel as null."""
    return None if x is None or not math.isfinite(x) else round(float(x), 3)


def _pair(p: tuple[float, float] | None) -> list[float] | None:
    return None if p is None else [_num(p[0]), _num(p[1])]


class MapStation:
    """The station side of the map: the session, the track it builds, and the snapshot the page draws."""

    def __init__(self, client: Client, out: TextIO = sys.stdout, linkmap: LinkMapSource | None = None) -> None:
        """``linkmap``: where the vehicle's link map comes from (CSV bytes; ``gcs/linkmap_layer.py``)."""
        self.client = client
        self.linkmap = linkmap
        self.track = Track()
        self.session = Session(client, out)
        self.plan = "not downloaded"
        self.plan_stale = True
        self.plan_total: int | None = None
        self.rtl_max_disp: float | None = None
        client.gs.listeners.append(self._on_message)

    def _on_message(self, m, t: float) -> None:
        kind = m.get_type()
        if kind == "LOCAL_POSITION_NED":
            self.track.add(t, m.x, m.y)
        elif kind == "MISSION_CURRENT" and m.total != self.plan_total:  # a plan uploaded or cleared by anyone
            self.plan_total, self.plan_stale = m.total, True
        elif kind == "STATUSTEXT":  # "return plan: ..." follows every accepted upload, same length or not
            text = m.text if isinstance(m.text, str) else m.text.decode("utf-8", "replace")
            if text.startswith("return plan:"):
                self.plan_stale = True

    def _refresh_plan(self) -> None:
        """Download the return plan (standard mission protocol) when it may have changed."""
        if not self.plan_stale:
            return
        self.plan_stale = False
        try:
            items = self.client.download()
            self.plan = describe(items) if items else "default plan (one return to link)"
        except GcsError as e:
            self.plan = f"unknown ({e})"

    def start(self) -> None:
        """Start the link thread, then read what the map needs once: the plan and the displacement limit."""
        self.session.__enter__()
        with self.session.lock:
            self._refresh_plan()
            try:
                self.rtl_max_disp = self.client.param_get("RTL_MAX_DISP")
            except GcsError:
                self.rtl_max_disp = None

    def stop(self) -> None:
        self.session.__exit__(None, None, None)

    def snapshot(self) -> dict:
        with self.session.lock:
            self._refresh_plan()
            c = self.client
            v = c.gs.vehicle
            st = v.status
            now = c.now
            pos = v.position
            state = {
                "t": round(now, 2),
                "vehicle": v.sysid, "armed": v.armed, "position": _pair(pos), "yaw": _num(v.yaw),
                "heard_s": None if v.last_heard is None else round(now - v.last_heard, 2),
                "trail": [[_num(p.north), _num(p.east), round(p.quality, 2)] for p in self.track.points],
                "lost": [[_num(p.north), _num(p.east), round(p.t, 1)] for p in self.track.lost],
                "plan": self.plan, "events": [], "texts": [t for _, t in c.gs.texts[-6:]],
                "lease": None, "route": [], "circle": None, "linkmap": self._linkmap(),
            }
            for e in c.gs.events[-8:]:
                state["events"].append(f"{e.t:7.1f}  {e.expired} -> {e.current}  {e.reason} ({e.holder})")
            if st is not None:
                state["lease"] = {
                    "epoch": st.epoch, "index": st.current, "claimed": st.claimed, "owner": st.owner,
                    "holder": st.holder, "state": st.state_name, "reason": st.reason_name,
                    "scheduled": st.scheduled, "link_age": _num(st.link_age), "trail_points": st.trail_points,
                    "displacement": _num(st.displacement), "max_displacement": _num(st.max_displacement),
                    "return_start": _pair(st.return_start), "return_target": _pair(st.return_target),
                    "route_remaining": _num(st.route_remaining),
                }
                if pos is not None:
                    state["route"] = [_pair(p) for p in return_route(self.track, pos, st.return_start,
                                                                     st.return_target, st.max_displacement)]
                if st.return_start is not None and math.isfinite(st.max_displacement):
                    state["circle"] = {"center": _pair(st.return_start), "radius": _num(st.max_displacement),
                                       "kind": "return"}
                elif pos is not None and self.rtl_max_disp is not None:
                    # no return running: how far one would be allowed to go if the link were lost here
                    state["circle"] = {"center": _pair(pos), "radius": _num(self.rtl_max_disp), "kind": "preview"}
            return state

    def _linkmap(self) -> dict | None:
        """The link layer (None: no source, or it has no map yet)."""
        data = self.linkmap() if self.linkmap is not None else None
        return None if data is None else layer(data)

    def act(self, name: str) -> tuple[bool, str]:
        with self.session.lock:
            try:
                if name == "acquire":
                    return True, f"in control: epoch {self.client.acquire()}"
                if name == "rtl":
                    self.client.rtl()
                    return True, "returning"
                if name == "hold":
                    self.client.hold()
                    return True, "holding"
                if name == "claim":
                    return True, f"claimed lease index {self.client.claim()}"
            except GcsError as e:
                return False, str(e)
            finally:
                self.session.report()
        return False, f"no action {name!r}"


def _handler(station: MapStation) -> type[BaseHTTPRequestHandler]:
    class Handler(BaseHTTPRequestHandler):
        def log_message(self, fmt: str, *args) -> None:  # the terminal shows lease events, not HTTP requests
            pass

        def _send(self, status: int, body: bytes, kind: str) -> None:
            self.send_response(status)
            self.send_header("Content-Type", kind)
            self.send_header("Content-Length", str(len(body)))
            self.send_header("Cache-Control", "no-store")
            self.end_headers()
            self.wfile.write(body)

        def _json(self, status: int, obj) -> None:
            self._send(status, json.dumps(obj).encode(), "application/json")

        def do_GET(self) -> None:  # noqa: N802 - http.server's name
            path = self.path.split("?", 1)[0]
            if path == "/state":
                self._json(HTTPStatus.OK, station.snapshot())
            elif path in STATIC:
                name, kind = STATIC[path]
                self._send(HTTPStatus.OK, (WEB / name).read_bytes(), kind)
            else:
                self._json(HTTPStatus.NOT_FOUND, {"error": f"no page {path}"})

        def do_POST(self) -> None:  # noqa: N802 - http.server's name
            path = self.path.split("?", 1)[0]
            name = path.removeprefix("/action/")
            if not path.startswith("/action/") or name not in ACTIONS:
                self._json(HTTPStatus.NOT_FOUND, {"ok": False, "message": f"no action {name!r}"})
                return
            ok, message = station.act(name)
            self._json(HTTPStatus.OK, {"ok": ok, "message": message})

    return Handler


class MapServer:
    """The HTTP side: bound to 127.0.0.1 only (the page can move the robot)."""

    def __init__(self, client: Client, port: int = 8080, out: TextIO = sys.stdout,
                 linkmap: LinkMapSource | None = None) -> None:
        self.station = MapStation(client, out, linkmap)
        self.httpd = ThreadingHTTPServer(("127.0.0.1", port), _handler(self.station))
        self.httpd.daemon_threads = True
        self.thread: threading.Thread | None = None

    @property
    def url(self) -> str:
        host, port = self.httpd.server_address[:2]
        return f"http://{host}:{port}/"

    def start(self) -> MapServer:
        """Serve in a background thread (for tests and embedding)."""
        self.station.start()
        self.thread = threading.Thread(target=self.httpd.serve_forever, name="gcs-map", daemon=True)
        self.thread.start()
        return self

    def close(self) -> None:
        self.httpd.shutdown()
        self.httpd.server_close()
        self.station.stop()


def serve_map(client: Client, port: int = 8080, linkmap: LinkMapSource | None = None) -> int:
    """``returnlink gcs map``: serve until Ctrl-C."""
    try:
        server = MapServer(client, port, linkmap=linkmap)
    except OSError as e:
        print(f"returnlink gcs: cannot serve the map on 127.0.0.1:{port}: {e}", file=sys.stderr)
        return 2
    server.start()
    print(f"returnlink gcs: map on {server.url} (Ctrl-C to stop)", file=sys.stderr, flush=True)
    try:
        threading.Event().wait()
    except KeyboardInterrupt:
        pass
    finally:
        server.close()
    return 0
