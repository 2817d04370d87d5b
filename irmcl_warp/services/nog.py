"""``bake_nog``: the NOG of a trained NOF, cached by the hash of the checkpoint file and the settings
(outputs/<exp>/nog/nog-<hash>.npz), so every stage that localizes with the same field bakes it once."""

from __future__ import annotations

from pathlib import Path

from irmcl_warp.nof.checkpoint import load_nof_for
from irmcl_warp.nog import NOG, evaluate_grid
from irmcl_warp.runs import digest, file_digest


def bake_nog(
    checkpoint: Path, bounds, far_m: float, resolution_m: float = 0.05, cache_dir: Path | None = None, device="cpu"
) -> NOG:
    """Bake (or read from the cache) the NOG of a nof.pt checkpoint, for localizing with the far bound ``far_m``
    (an error when the NOF was trained with another: nof/checkpoint.check_trained_far_bound)."""
    model, _ = load_nof_for(checkpoint, far_m, "cpu")  # checked even when the NOG is cached; evaluate_grid moves it
    key = digest([file_digest(checkpoint), [float(b) for b in bounds], float(resolution_m)])[:16]
    path = Path(cache_dir) / f"nog-{key}.npz" if cache_dir else None
    if path is not None and path.is_file():
        try:
            return NOG.load(path)
        except (OSError, KeyError, ValueError):
            pass  # unreadable cache (interrupted write of an older version): bake again
    nog = evaluate_grid(model, bounds, resolution_m, device)
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        nog.save(path)
    return nog
