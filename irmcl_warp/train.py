"""``python -m irmcl_warp.train +exp=<name> [train=paper|fast|cpu|quick]``: see irmcl_warp/nof/stage.py."""

import hydra

from irmcl_warp.config import register
from irmcl_warp.nof.stage import run_train
from irmcl_warp.services.cli import hydra_main, run_entry

register()


@hydra.main(version_base="1.3", config_path="pkg://irmcl_warp.conf", config_name="config")
def main(cfg) -> None:
    run_entry(run_train, cfg)


if __name__ == "__main__":
    hydra_main(main)
