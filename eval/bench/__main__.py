"""``python -m eval.bench train|mlp|mcl|estimate|slam|globloc|sweeps ...``: see each module's docstring."""

import argparse

from eval.bench import estimate, globloc, mcl, mlp, slam, sweeps, train
from irmcl_warp.services.cli import guard


def main(argv=None):
    ap = argparse.ArgumentParser(prog="python -m eval.bench")
    sub = ap.add_subparsers(dest="what", required=True)
    train.add_parser(sub)
    mlp.add_parser(sub)
    mcl.add_parser(sub)
    estimate.add_parser(sub)
    slam.add_parser(sub)
    globloc.add_parser(sub)
    sweeps.add_parser(sub)
    a = ap.parse_args(argv)
    if a.what == "train":
        if a.exp and not a.init:
            ap.error("--exp needs --init <trained nof.pt>")
        train.run_train_bench(a)
    else:
        {
            "mlp": mlp.run_mlp_bench,
            "mcl": mcl.run_mcl_bench,
            "estimate": estimate.run_estimate_bench,
            "slam": slam.run_slam_bench,
            "globloc": globloc.run_globloc_bench,
            "sweeps": sweeps.run_sweeps_bench,
        }[a.what](a)


if __name__ == "__main__":
    guard(main)
