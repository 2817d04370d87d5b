"""Writing a run's files: JSON and figures, each written atomically (temporary file + rename), so an
interrupted run never leaves a half-written file. Where runs live and what makes one finished is
``irmcl_warp.runs``."""

from __future__ import annotations

from pathlib import Path

from irmcl_warp.io.atomic import atomic_write_bytes
from irmcl_warp.io.atomic import atomic_write_json as write_json  # noqa: F401  (the name the stages use)


def save_figure(fig, path) -> Path:
    """A matplotlib figure as PNG, written atomically, then closed."""
    import io

    import matplotlib.pyplot as plt

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110, bbox_inches="tight")
    plt.close(fig)
    atomic_write_bytes(Path(path), buf.getvalue())
    return Path(path)
