"""How the localize stage's run folders name particle counts and map resolutions (the tables read them
back the same way)."""

from __future__ import annotations


def particles_tag(n: int) -> str:
    """A particle count as run folders name it: ``100k``, ``2500``."""
    return f"{n // 1000}k" if n % 1000 == 0 else str(n)


def resolution_tag(res_m: float) -> str:
    """A map resolution in cm as run folders and tables name it: ``5``, ``2.5``."""
    cm = res_m * 100
    return str(round(cm)) if abs(cm - round(cm)) < 1e-6 else f"{cm:g}"
