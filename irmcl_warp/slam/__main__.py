"""``python -m irmcl_warp.slam +exp=gmapping_intel``: see irmcl_warp/slam/stage.py."""

import hydra

from irmcl_warp.config import register
from irmcl_warp.slam.stage import run_slam
from irmcl_warp.services.cli import hydra_main, run_entry

register()


@hydra.main(version_base="1.3", config_path="pkg://irmcl_warp.conf", config_name="config")
def main(cfg) -> None:
    run_entry(run_slam, cfg)


if __name__ == "__main__":
    hydra_main(main)
