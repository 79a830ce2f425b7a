"""Worlds from an owner's own map (docs/architecture.md §7.2): a ROS map_server map (a YAML file and its image) read
as ROS reads it (``mapfile``), its occupied cells as the robot's walls and the radio's obstacles on the grid
(``grid``), the predicted coverage from a station (``coverage``), routes planned over its free space to places
where the link dies (``routes``), the `site survey` campaign (``survey``) and the radio model fitted to a logged
drive (``fit``, ``tlog``).
"""
