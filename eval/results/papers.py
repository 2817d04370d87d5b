"""The papers' published figures (papers.yaml): ``figure(name)`` gives value, unit, paper and where it is
printed; ``cite(name)`` the figure as a table writes it ("0.250 m (irmcl, Table I, ...)")."""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path

PAPERS_FILE = Path(__file__).with_name("papers.yaml")


@dataclass(frozen=True)
class Figure:
    name: str
    value: str  # as printed ("0.250", "60-80")
    unit: str
    paper: str
    where: str

    @property
    def number(self) -> float:
        return float(self.value)

    def text(self) -> str:
        """As the paper prints it (papers.yaml keeps the printed digits: "0.250")."""
        return f"{self.value} {self.unit}"


@functools.lru_cache(maxsize=None)
def _load() -> tuple[dict, dict]:
    from omegaconf import OmegaConf

    doc = OmegaConf.to_container(OmegaConf.load(PAPERS_FILE))
    figures = {k: Figure(k, str(v["value"]), v["unit"], v["paper"], v["where"]) for k, v in doc["figures"].items()}
    unknown = sorted({f.paper for f in figures.values()} - set(doc["papers"]))
    if unknown:
        raise ValueError(f"{PAPERS_FILE}: figures cite papers it does not list: {unknown}")
    return doc["papers"], figures


def papers() -> dict[str, str]:
    return _load()[0]


def figure(name: str) -> Figure:
    figures = _load()[1]
    if name not in figures:
        raise KeyError(f"{PAPERS_FILE} has no figure {name!r}")
    return figures[name]
