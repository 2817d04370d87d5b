"""The ``pool`` launcher's settings (``hydra/launcher=pool``, then ``hydra.launcher.<key>=...``)."""

from dataclasses import dataclass
from typing import Optional

from hydra.core.config_store import ConfigStore


@dataclass
class PoolLauncherConf:
    _target_: str = "hydra_plugins.irmcl_warp_pool.pool.PoolLauncher"
    # GPUs to spread the jobs over: null = every GPU this process sees (CUDA_VISIBLE_DEVICES, else nvidia-smi);
    # 0 = run on CPU workers even where there are GPUs
    gpus: Optional[int] = None
    # processes per GPU at once (small jobs leave a GPU mostly idle: 2-4 keep it busier)
    jobs_per_gpu: int = 1
    # processes at once where no GPU is used: null = half the cores (at least one)
    cpu_workers: Optional[int] = None
    # a job that fails (exit status not 0, or over timeout_min) is started again this many times
    retries: int = 1
    # a job running longer than this many minutes is stopped and counts as failed; null = no limit
    timeout_min: Optional[float] = None
    # lines of a failed job's log shown in the report
    tail_lines: int = 25


ConfigStore.instance().store(group="hydra/launcher", name="pool", node=PoolLauncherConf, provider="irmcl_warp")
