"""The real ArduPilot Rover firmware in returnlink's worlds (docs/architecture.md §10).

The firmware is a separate process, never linked or copied: ``locate`` finds its binary, ``process`` starts it in
its own directory with an instance number no other run holds and stops it by process id, ``bridge`` is the JSON
SITL backend's packet contract (pure), ``operator`` the scripted ground station that reaches the firmware only
through the radio model, ``run`` the lockstep loop that ties them to a scenario's pymunk world, and ``metrics`` and
``report`` turn a run into the §7 figures and its plots.
"""
