"""The real ArduPilot Rover firmware in returnlink's worlds (docs/architecture.md §10).

The firmware is a separate process, never linked or copied: ``locate`` finds its binary, ``process`` starts it in
its own directory with an instance number no other run holds and stops it by process id, ``bridge`` is the JSON
SITL backend's packet contract (pure), ``lockstep`` the firmware and its pymunk physics in lockstep, ``operator`` and
``companion_operator`` the scripted ground stations that reach it only through the radio model, ``metrics`` its
figures read from its modes, ``report`` its plots. What flies it in a scenario is a plant of the one simulator loop
(``sim.plants.firmware``, ``sim.plants.companion``, driven by ``sim.runner.Run``, or in real time for a ground
station of your own by ``sim.serve.Server``; ``sim.firmware_runs`` names those runs as their callers know
them).
"""
