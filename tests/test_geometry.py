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
    np.testing.assert_allclose(
        transform_points(np.array([1.0, 0, np.pi / 2]), np.array([[1.0, 0]])), [[1, 1]], atol=1e-12
    )


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


def test_relative_of_one_pair_is_relatives_bits(rng):
    """RBPF.step queues each scan's odometry step through relative_one; its bits must be relative()'s, or the
    particles' draws move. Far from the origin (a log hundreds of metres out) and across +-pi."""
    from irmcl_warp.geometry import relative_one, wrap_angle_one

    n = 2000
    a = np.c_[rng.uniform(-700, 700, (n, 2)), rng.uniform(-np.pi, np.pi, n)]
    b = a + np.c_[rng.normal(0, 0.05, (n, 2)), rng.normal(0, 0.3, n)]
    b[: n // 4, 2] = wrap_angle(b[: n // 4, 2] + np.pi)  # some steps cross the wrap
    want = relative(a, b)
    got = np.array([relative_one(tuple(map(float, p)), tuple(map(float, q))) for p, q in zip(a, b)])
    assert np.array_equal(got, want)
    d = b[:, 2] - a[:, 2]
    assert np.array_equal([wrap_angle_one(float(v)) for v in d], wrap_angle(d))
