"""Analyses of runs beyond the tables (``python -m eval.analyses.<name>``): determinism (a seed replays bit for
bit), fuzz (the readers against damaged files), yaw_lag (a localization's heading error over time), rescore
(runs scored again), rerun (kept SLAM runs made again and compared)."""
