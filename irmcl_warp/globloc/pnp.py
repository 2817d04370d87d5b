"""Pose from a keyframe: ORB features of the query and the keyframe, Lowe's ratio test, the keyframe's 3D
points from its depth, RANSAC PnP (OpenCV), and the camera pose brought back to the robot's (x, y, yaw).

Frames: the robot's map frame is x, y on the floor, z up; a camera at (x, y, yaw) and height h looks
along its yaw; OpenCV's camera frame is x right, y down, z forward.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from irmcl_warp.geometry import compose, inverse


@dataclass
class PnPResult:
    pose: np.ndarray | None  # robot pose (x, y, yaw), None when not accepted
    inliers: int
    matches: int


def camera_to_world(cam_pose, cam_height: float) -> tuple[np.ndarray, np.ndarray]:
    """(R [3, 3], t [3]) with X_world = R X_cam + t for a camera at (x, y, yaw) and height h."""
    x, y, yaw = cam_pose
    c, s = np.cos(yaw), np.sin(yaw)
    forward, left, up = np.array([c, s, 0.0]), np.array([-s, c, 0.0]), np.array([0.0, 0.0, 1.0])
    R = np.column_stack([-left, -up, forward])  # camera x = right = -left, y = down = -up, z = forward
    return R, np.array([x, y, cam_height])


def depth_at(depth: np.ndarray, uv: np.ndarray, edge_ratio: float) -> tuple[np.ndarray, np.ndarray]:
    """Depth at pixels uv [N, 2] (OpenCV coordinates) and whether it can be trusted: finite, positive, and
    not on a depth edge. ORB's corners sit on silhouettes, where the nearest pixel may belong to the wall
    behind; such a point passes RANSAC (it lies on the right ray) but pulls the translation along the ray,
    so a point whose 3x3 neighbourhood spans more than ``edge_ratio`` (max / min depth) is dropped."""
    H, W = depth.shape
    px = np.clip(np.round(uv).astype(int), 0, [W - 1, H - 1])
    z = depth[px[:, 1], px[:, 0]]
    lo, hi = np.full(len(z), np.inf), np.zeros(len(z))
    for dv in (-1, 0, 1):
        for du in (-1, 0, 1):
            n = depth[np.clip(px[:, 1] + dv, 0, H - 1), np.clip(px[:, 0] + du, 0, W - 1)]
            lo, hi = np.minimum(lo, n), np.maximum(hi, n)
    ok = np.isfinite(z) & (z > 0.05) & (lo > 0.05) & (hi <= edge_ratio * lo)
    return z, ok


def backproject(uv: np.ndarray, depth: np.ndarray, K: np.ndarray) -> np.ndarray:
    """Camera-frame points [N, 3] of pixels uv [N, 2] with z-depths [N]."""
    z = np.asarray(depth, np.float64)
    return np.column_stack([(uv[:, 0] - K[0, 2]) * z / K[0, 0], (uv[:, 1] - K[1, 2]) * z / K[1, 1], z])


class OrbPnP:
    def __init__(
        self,
        K: np.ndarray,
        cam_height_m: float,
        T_base_cam,
        n_features: int = 1000,
        ratio: float = 0.8,
        min_inliers: int = 12,
        reproj_px: float = 3.0,
        edge_ratio: float = 1.1,
        refine_px: float = 1.5,
    ):
        import cv2

        self.cv2, self.K = cv2, np.asarray(K, np.float64)
        self.cam_height, self.T_base_cam = float(cam_height_m), np.asarray(T_base_cam, np.float64)
        self.orb = cv2.ORB_create(nfeatures=n_features)
        self.matcher = cv2.BFMatcher(cv2.NORM_HAMMING)
        self.ratio, self.min_inliers, self.reproj = float(ratio), int(min_inliers), float(reproj_px)
        self.edge_ratio, self.refine_px = float(edge_ratio), float(refine_px)

    def features(self, rgb: np.ndarray):
        gray = self.cv2.cvtColor(np.ascontiguousarray(rgb, np.uint8), self.cv2.COLOR_RGB2GRAY)
        kp, des = self.orb.detectAndCompute(gray, None)
        return np.array([k.pt for k in kp], np.float64).reshape(-1, 2), des

    def solve(
        self, query, keyframe_rgb: np.ndarray, keyframe_depth: np.ndarray, keyframe_robot_pose, keyframe_features=None
    ) -> PnPResult:
        """Robot pose of the query (its features from ``features``, or its RGB image) from one keyframe."""
        q_uv, q_des = query if isinstance(query, tuple) else self.features(query)
        k_uv, k_des = keyframe_features if keyframe_features is not None else self.features(keyframe_rgb)
        if q_des is None or k_des is None or len(q_des) < 2 or len(k_des) < 2:
            return PnPResult(None, 0, 0)
        good = [
            m[0]
            for m in self.matcher.knnMatch(q_des, k_des, k=2)
            if len(m) == 2 and m[0].distance < self.ratio * m[1].distance
        ]
        if len(good) < max(self.min_inliers, 6):
            return PnPResult(None, 0, len(good))
        qi = np.array([m.queryIdx for m in good])
        ki = np.array([m.trainIdx for m in good])
        kuv = k_uv[ki]
        z, ok = depth_at(keyframe_depth, kuv, self.edge_ratio)
        if ok.sum() < max(self.min_inliers, 6):
            return PnPResult(None, 0, len(good))
        R, t = camera_to_world(compose(np.asarray(keyframe_robot_pose, np.float64), self.T_base_cam), self.cam_height)
        X = backproject(kuv[ok], z[ok], self.K) @ R.T + t  # float64
        found, rvec, tvec, inl = self.cv2.solvePnPRansac(
            X.astype(np.float64),
            q_uv[qi[ok]].astype(np.float64),
            self.K,
            None,
            reprojectionError=self.reproj,
            iterationsCount=200,
            flags=self.cv2.SOLVEPNP_EPNP,
        )
        n_in = 0 if inl is None else len(inl)
        if not found or n_in <= self.min_inliers:
            return PnPResult(None, n_in, len(good))
        uv = q_uv[qi[ok]].astype(np.float64)
        i = inl.reshape(-1)  # Levenberg-Marquardt on the inliers (EPnP's minimal-set pose is coarse), then again
        for _ in range(2):  # on the points within a tighter bound of the refined pose
            rvec, tvec = self.cv2.solvePnPRefineLM(X[i], uv[i], self.K, None, rvec, tvec)
            proj, _ = self.cv2.projectPoints(X, rvec, tvec, self.K, None)
            tight = np.flatnonzero(np.linalg.norm(proj.reshape(-1, 2) - uv, axis=1) < self.refine_px)
            if len(tight) <= self.min_inliers:
                break
            i = tight
        Rwc, _ = self.cv2.Rodrigues(rvec)  # world -> camera
        centre = -Rwc.T @ tvec.reshape(3)
        fwd = Rwc.T @ np.array([0.0, 0.0, 1.0])
        cam = np.array([centre[0], centre[1], np.arctan2(fwd[1], fwd[0])])
        return PnPResult(compose(cam, inverse(self.T_base_cam)), n_in, len(good))
