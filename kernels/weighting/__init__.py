"""Particle weighting for MCL, one file per observation model, each registered in ``WEIGHTING``:

* ``nog_raymarch`` (nog_raymarch.py): IR-MCL's observation model, a march through the NOG per particle and
  beam (the default);
* ``nog_table`` (nog_table.py): the same march run once into a range table, read per beam (an approximation);
* ``likelihood_field`` (likelihood_field.py) and ``beam_model`` (beam_model.py): AMCL's grid baselines;
* common.py: the laser's pose and rays, the nearest NOG node, IR-MCL's eq. 6, the grid models' launch.

A new observation model is a file like these plus its registration (docs/ARCHITECTURE.md, "Where to add X");
its numpy twin goes in irmcl_warp/reference/weighting.py and its parity test in tests/test_weighting.py.
"""

# importing the files registers their entries; the names below are this package's interface
from irmcl_warp.kernels.weighting.common import (
    nearest_node,
    laser_pose,
    beam_origin,
    beam_direction,
    slab,
    mean_l1_log_weight,
    make_likelihood_kernel,
    GridModel,
)
from irmcl_warp.kernels.weighting.nog_raymarch import (
    make_render_kernel,
    pack_empty_space,
    NogRaymarch,
    make_nog_raymarch,
)
from irmcl_warp.kernels.weighting.nog_table import (
    TABLE_LEVELS,
    TABLE_MAX_BYTES,
    TABLE_BUILD_FLOATS,
    quantize_ranges,
    table_range,
    table_ranges,
    make_table_likelihood_kernel,
    NogTable,
    table_headings,
    make_nog_table,
)
from irmcl_warp.kernels.weighting.likelihood_field import (
    make_log_q_kernel,
    likelihood_field_kernel,
    LikelihoodField,
    make_likelihood_field,
)
from irmcl_warp.kernels.weighting.beam_model import make_beam_model_kernel, BeamModel, make_beam_model

__all__ = [
    "nearest_node",
    "laser_pose",
    "beam_origin",
    "beam_direction",
    "slab",
    "mean_l1_log_weight",
    "make_likelihood_kernel",
    "GridModel",
    "make_render_kernel",
    "pack_empty_space",
    "NogRaymarch",
    "make_nog_raymarch",
    "TABLE_LEVELS",
    "TABLE_MAX_BYTES",
    "TABLE_BUILD_FLOATS",
    "quantize_ranges",
    "table_range",
    "table_ranges",
    "make_table_likelihood_kernel",
    "NogTable",
    "table_headings",
    "make_nog_table",
    "make_log_q_kernel",
    "likelihood_field_kernel",
    "LikelihoodField",
    "make_likelihood_field",
    "make_beam_model_kernel",
    "BeamModel",
    "make_beam_model",
]
