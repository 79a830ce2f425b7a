"""Simulation: pymunk world, robot models, sensors, scenarios, lockstep runner and real-time server."""
