"""Onboard software: runs on a real robot's companion computer as well as in simulation (never imports sim)."""
