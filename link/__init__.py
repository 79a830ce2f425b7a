"""Everything between the ground station and the vehicle: the dialect, transports, radio model and proxy."""
