import numpy as np


def Vector3dVector(points):  # noqa: N802 (open3d's name)
    return np.asarray(points, dtype=np.float64).reshape(-1, 3)
