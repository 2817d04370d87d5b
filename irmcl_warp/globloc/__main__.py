"""``python -m irmcl_warp.globloc +exp=globloc_corridor``: see irmcl_warp/globloc/run.py."""

import hydra

from irmcl_warp.config import register
from irmcl_warp.globloc.run import run_globloc
from irmcl_warp.services.cli import hydra_main, run_entry

register()


@hydra.main(version_base="1.3", config_path="pkg://irmcl_warp.conf", config_name="config")
def main(cfg) -> None:
    run_entry(run_globloc, cfg)


if __name__ == "__main__":
    hydra_main(main)
