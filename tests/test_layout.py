from pathlib import Path

import kernels

REPO = Path(__file__).resolve().parents[1]


def test_kernels_package_is_ours_not_the_pypi_one():
    assert Path(kernels.__file__).resolve().is_relative_to(REPO)


def test_every_registry_entry_has_a_reference_twin():
    import irmcl_warp.nof.direct  # noqa: F401  (nof_direct runs the torch MLP: it registers from nof/)
    from kernels import ESTIMATE, MAPPING, MOTION, RAYCAST, RENDER, RESAMPLE, SIM, SLAM, WEIGHTING

    assert RAYCAST.names() == ["dda", "distance_field"]
    assert MAPPING.names() == ["logodds"]
    assert SIM.names() == ["camera", "rasterize", "segment_lidar"]
    assert RENDER.names() == ["composite", "occupied_samples"]
    assert WEIGHTING.names() == ["beam_model", "likelihood_field", "nof_direct", "nog_raymarch", "nog_table"]
    assert MOTION.names() == ["irmcl", "odometry"] and RESAMPLE.names() == ["low_variance", "multinomial"]
    from irmcl_warp.reference import motion

    assert callable(motion.sample_irmcl) and callable(motion.sample_odometry)  # one twin per motion model
    assert ESTIMATE.names() == ["best_cluster", "top_share"]
    assert SLAM.names() == ["integrate", "motion", "score"]
    for twin in ("raycast", "mapping", "sim", "camera", "render", "weighting", "motion", "resample", "estimate", "slam"):
        assert (REPO / "irmcl_warp" / "reference" / f"{twin}.py").is_file()
