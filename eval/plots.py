"""``python -m eval.plots``: every figure (eval/report/plots.py)."""

from eval.report.plots import main
from irmcl_warp.services.cli import guard

if __name__ == "__main__":
    guard(main)
