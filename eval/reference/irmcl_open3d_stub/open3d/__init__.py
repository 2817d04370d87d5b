"""A stand-in for the three open3d calls the authors' NOF code makes (nof/criteria/pointcloud_metrics.py: a point
cloud, its KD-tree, one nearest neighbour per query), for machines where open3d cannot be installed (the GPU
machines: its wheel is larger than a transfer). Nearest neighbours by scipy's cKDTree: the same distances.
Ours; eval/reference/irmcl.py puts it on the path of their training run only."""

from . import geometry, utility  # noqa: F401
