"""Companion mode (docs/architecture.md §11): returnlink's onboard software on a companion computer beside an unmodified
ArduPilot Rover, between the autopilot's telemetry port and the ground-station radio.

``router`` decides what passes between the ground and the autopilot (pure), ``autopilot`` is the ``RobotDriver``
over MAVLink to the autopilot, ``app`` wires them to the very ``Vehicle`` and ``Endpoint`` the native vehicle runs,
``links`` opens the connections named on the command line and ``cli`` is ``returnlink companion``.
"""
