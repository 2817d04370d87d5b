import numpy as np
import pytest

from irmcl_warp.geometry import compose, interpolate_poses, inverse, relative, transform_points, wrap_angle


def test_compose_inverse_roundtrip(rng):
    a = np.c_[rng.normal(size=(50, 2)) * 10, rng.uniform(-np.pi, np.pi, 50)]
    b = np.c_[rng.normal(size=(50, 2)) * 10, rng.uniform(-np.pi, np.pi, 50)]
    np.testing.assert_allclose(compose(inverse(a), a), 0, atol=1e-12)
    np.testing.assert_allclose(compose(a, relative(a, b)), b, atol=1e-9)


def test_hand_computed_compose_and_points():
    # a quarter turn at (1, 0): the point 1 m ahead of it lies at (1, 1)
    np.testing.assert_allclose(compose([1, 0, np.pi / 2], [1, 0, 0]), [1, 1, np.pi / 2], atol=1e-12)
    np.testing.assert_allclose(transform_points(np.array([1.0, 0, np.pi / 2]), np.array([[1.0, 0]])), [[1, 1]], atol=1e-12)


def test_interpolation_takes_the_short_way_across_pi():
    out = interpolate_poses([0.0, 1.0], np.array([[0, 0, np.pi - 0.1], [2, 0, -np.pi + 0.1]]), [0.5])
    assert abs(abs(out[0, 2]) - np.pi) < 1e-9 and out[0, 0] == 1.0
    assert np.all(np.abs(wrap_angle(np.array([3 * np.pi, -3 * np.pi]))) <= np.pi)


def test_rigid_alignment_recovers_a_random_motion(rng):
    from irmcl_warp.geometry import align_rigid

    est = np.column_stack([rng.uniform(-20, 20, (50, 2)), rng.uniform(-np.pi, np.pi, 50)])
    T = np.array([rng.uniform(-10, 10), rng.uniform(-10, 10), rng.uniform(-np.pi, np.pi)])
    ref = compose(T, est)
    ref[::7] = np.nan  # rows unknown in one trajectory are ignored
    got = align_rigid(est, ref)
    assert np.allclose(got[:2], T[:2], atol=1e-9) and abs(wrap_angle(got[2] - T[2])) < 1e-9, f"seed {rng.seed}"
    with pytest.raises(ValueError, match="two poses"):
        align_rigid(est[:1], ref[:1])
