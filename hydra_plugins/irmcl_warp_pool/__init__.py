"""irmcl-warp's local sweep launcher for Hydra (``hydra/launcher=pool``): each job of a multirun is a process of
its own, one per GPU on a multi-GPU host (``CUDA_VISIBLE_DEVICES`` set per worker) or a pool of CPU workers
elsewhere, with progress, a log file per job, retries and a report of what failed. See pool.py."""
