import numpy as np
from scipy.spatial import cKDTree


class PointCloud:
    def __init__(self):
        self.points = np.empty((0, 3))


class KDTreeFlann:
    def __init__(self, cloud: PointCloud):
        self._tree = cKDTree(np.asarray(cloud.points, dtype=np.float64))

    def search_knn_vector_3d(self, query, knn: int):
        """(count, indices, squared distances), as open3d returns them."""
        dist, idx = self._tree.query(np.asarray(query, dtype=np.float64), k=knn)
        dist, idx = np.atleast_1d(dist), np.atleast_1d(idx)
        return len(idx), [int(i) for i in idx], [float(d) ** 2 for d in dist]
