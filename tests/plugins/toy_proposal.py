"""A SLAM proposal of your own, as a plugin (irmcl_warp/extend.py): the motion model's sample kept as it is and
weighed by the scan's likelihood in the particle's own map (the paper's odometry baseline, written outside the
package), counting its calls:

    python -m irmcl_warp.slam plugins=[tests/plugins/toy_proposal.py] slam.proposal=toy_odometry ...
"""

from irmcl_warp.slam.rbpf import PROPOSALS

CALLS = [0]


@PROPOSALS.register("toy_odometry")
def make_toy(rbpf):
    def propose(sampled, moved):
        CALLS[0] += 1
        return sampled, rbpf.loglik_at(sampled[:, None])[:, 0], 0

    return propose
