"""``python -m irmcl_warp.worlds +exp=worlds [worlds.split=tuning|test] [mcl.*=...]``: see irmcl_warp/mcl/worlds.py."""

import hydra

from irmcl_warp.config import register
from irmcl_warp.mcl.worlds import run_worlds
from irmcl_warp.services.cli import hydra_main, run_entry

register()


@hydra.main(version_base="1.3", config_path="pkg://irmcl_warp.conf", config_name="config")
def main(cfg) -> None:
    run_entry(run_worlds, cfg)


if __name__ == "__main__":
    hydra_main(main)
