"""Occupancy-grid mapping with known poses, and map files (ROS map_server PGM+YAML, .npz, PNG)."""

from irmcl_warp.mapping.grid import OccupancyGrid, build_map, grid_bounds, integrate_scans
from irmcl_warp.mapping.mapio import load_map, save_map

__all__ = ["OccupancyGrid", "build_map", "grid_bounds", "integrate_scans", "load_map", "save_map"]
