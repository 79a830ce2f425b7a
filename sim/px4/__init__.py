"""The real PX4 rover in returnlink's worlds (docs/architecture.md §10.1), the foundation: PX4 drives a rover model
through its simulator interface (HIL MAVLink over TCP), in lockstep.

PX4 is a separate process, never linked or copied: ``locate`` finds it (a directory with ``bin/px4`` and ``etc/``),
``process`` starts one per run in its own work directory on an instance no other run holds and stops it by process
id, ``hil`` is the simulator side of the HIL messages as pure functions (the rover's state -> HIL_SENSOR and
HIL_GPS, HIL_ACTUATOR_CONTROLS -> the rover's command), and ``bridge`` the TCP server PX4 connects to, one
``step`` per physics step. ``lockstep`` puts them together for a plant on the simulator loop (PX4, its bridge, a
robot and PX4's GCS link; ``sim.plants.px4``), and ``operator`` is the scripted ground station that flies PX4 in
Offboard there.
"""
