import re
from pathlib import Path

import irmcl_warp.kernels

REPO = Path(__file__).resolve().parents[1]


def test_the_kernels_live_in_the_top_level_folder_and_are_imported_inside_the_package():
    """The repository keeps kernels/ at its top level; the package reaches it as ``irmcl_warp.kernels`` (a link
    in the checkout, a subpackage in the wheel), so nothing is installed under the name ``kernels`` that another
    distribution on the index uses, and no module imports the folder under its top-level name."""
    assert Path(irmcl_warp.kernels.__file__).resolve() == REPO / "kernels" / "__init__.py"
    top_level = re.compile(r"^\s*(from|import) kernels\b", re.M)
    found = [
        str(p.relative_to(REPO))
        for folder in ("irmcl_warp", "kernels", "eval", "tests", "hydra_plugins")
        for p in (REPO / folder).rglob("*.py")
        if top_level.search(p.read_text())
    ]
    assert found == []


def test_every_registry_entry_has_a_reference_twin():
    import irmcl_warp.nof.direct  # noqa: F401  (nof_direct runs the torch MLP: it registers from nof/)
    from irmcl_warp.kernels import ESTIMATE, MAPPING, MOTION, RAYCAST, RENDER, RESAMPLE, SIM, SLAM, WEIGHTING

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
    for twin in (
        "raycast",
        "mapping",
        "sim",
        "camera",
        "render",
        "weighting",
        "motion",
        "resample",
        "estimate",
        "slam",
    ):
        assert (REPO / "irmcl_warp" / "reference" / f"{twin}.py").is_file()
