"""``python -m eval.analyses.fuzz [--cases N] [--seed S] [--write]``: every reader against corrupted input, counted.

The corruption classes (issue 16) and what a reader must do with each: fail with a ``LogFormatError`` (or
``ValueError`` / ``FileNotFoundError``) naming the file, or warn (``LogDefectWarning``) naming the file, or
return exactly what the intact file says. A text reader has no checksum, so a digit turned into another digit
is out of scope; so is a minus sign turned into a space. In scope:

* ``cut``: the file cut at any byte. The intact lines before the cut must come back (or an error where they
  alone are no valid file), an unfinished last line dropped loudly; a compressed file cut is an error.
* ``replaced`` / ``inserted``: a byte replaced by, or a byte inserted as, a character no number contains
  (``x``, NUL, 0xFF, broken UTF-8, ``;``, ``,``, brackets, ``nan``, ``inf``; inserted also space, tab,
  line break: they split a token or a line).
* ``archive``: a byte of a gzip or zip file flipped.
* ``random``: random bytes under the reader's file name.

Outcomes: ``error`` and ``warning`` (loud, naming the file), ``intact`` (the read equals the intact file's),
``silent wrong`` and ``unexpected`` (another exception type, or an error or warning without the file name):
the last two must stay at zero. tests/test_fuzz_readers.py drives the same classes through hypothesis in
CI; this command counts outcomes over seeded cases and writes docs/reader-fuzz.md and results/readers/fuzz.json.
"""

from __future__ import annotations

import argparse
import gzip
import io
import json
import tempfile
import warnings
import zipfile
from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from irmcl_warp.io import (
    LogDefectWarning,
    LogFormatError,
    read_carmen,
    read_carmen_poses,
    read_g2o,
    read_matched_csv,
    read_relations,
    read_splits,
    read_tum,
)
from irmcl_warp.io.atomic import atomic_write_bytes
from irmcl_warp.mapping.mapio import load_map
from irmcl_warp.services.cli import guard

REPO = Path(__file__).resolve().parents[2]

# ---------------------------------------------------------------- intact files, one per reader


def carmen_text(n=8, beams=7):
    lines = ["# CARMEN log\n", "PARAM robot_width 0.4\n"]
    for k in range(n):
        t = 100.0 + 0.2 * k
        r = " ".join(f"{1.0 + 0.1 * b + 0.01 * k:.2f}" for b in range(beams - 1)) + " 81.91"
        pose = f"{0.1 * k:.4f} {-0.05 * k:.4f} {0.02 * k:.4f}"
        lines.append(f"FLASER {beams} {r} {pose} {pose} {t:.6f} host {t:.6f}\n")
        lines.append(f"ODOM {0.1 * k:.4f} 0.0000 0.0000 0.5 0 0 {t + 0.1:.6f} host 0\n")
    return "".join(lines)


def tum_text(n=12):
    return "# stamp x y z qx qy qz qw\n" + "".join(
        f"{10 + 0.5 * k:.6f} {0.3 * k:.4f} {-0.2 * k:.4f} 0 0 0 {np.sin(0.1 * k):.6f} {np.cos(0.1 * k):.6f}\n"
        for k in range(n)
    )


def csv_text(n=12):
    return "bag_scan_index,ipc_stamp,x,y,theta\n" + "".join(
        f"{3 * k},{500 + 0.4 * k:.6f},{0.5 * k:.4f},{-1.5 + 0.1 * k:.4f},{-0.3 + 0.05 * k:.4f}\n" for k in range(n)
    )


def relations_text(n=12):
    return "".join(
        f"{100 + k:.6f} {102.5 + k:.6f} {0.4 + 0.01 * k:.6f} {-0.2:.6f} 0 0 0 {0.1 - 0.02 * k:.6f}\n" for k in range(n)
    )


def splits_text():
    stamps = [round(100 + 0.2 * k, 6) for k in range(30)]
    return (
        json.dumps(
            {
                "source": "fuzz",
                "train": stamps[:20],
                "val": stamps[20:25],
                "test": stamps[25:],
                "test_block": stamps[24:],
            },
            indent=1,
        )
        + "\n"
    )


def g2o_text(n=6):
    lines = ["# g2o\n"]
    for k in range(n):
        lines.append(f"VERTEX_SE2 {k} {0.5 * k:.4f} {0.1 * k:.4f} {0.05 * k:.4f}\n")
    for k in range(n - 1):
        lines.append(f"EDGE_SE2 {k} {k + 1} 0.5000 0.1000 0.0500 100 0 0 100 0 1000\n")
    for k in range(n):
        r = " ".join(f"{2 + 0.1 * b:.2f}" for b in range(5))
        lines.append(
            f"ROBOTLASER1 0 -1.5708 3.1416 0.7854 50 0.01 0 5 {r} 0 0 0 0 0 0 0 0 0 0 0 0 "
            f"{200 + k:.6f} host {200 + k:.6f}\n"
        )
    return "".join(lines)


def map_yaml_text():
    return (
        "image: m.pgm\nresolution: 0.05\norigin: [-1.5, -2.25, 0.0]\nnegate: 0\noccupied_thresh: 0.65\n"
        "free_thresh: 0.196\nmode: trinary\n"
    )


def pgm_bytes():
    img = np.full((6, 8), 254, np.uint8)
    img[2, 3:6] = 0
    img[4, 1] = 205
    return b"P5\n# a comment\n8 6\n255\n" + img.tobytes()


def _arrays(x):
    if isinstance(x, tuple):
        return [a for item in x for a in _arrays(item)]
    if isinstance(x, dict):
        return [np.asarray(sorted(x))] + [np.asarray(x[k]) for k in sorted(x)]
    if hasattr(x, "ranges_m"):  # LaserLog
        return [
            x.stamps,
            x.ranges_m,
            x.odom,
            np.asarray(x.info.angles_rad),
            np.asarray([x.info.no_return_m]),
            x.T_base_laser,
        ]
    if hasattr(x, "motion"):  # Relations
        return [x.t1, x.t2, x.motion]
    if hasattr(x, "vertex_ids"):  # G2oGraph
        return [x.vertex_ids, x.vertex_poses, x.edges, x.laser_stamps, *x.laser_ranges]
    if hasattr(x, "logodds"):  # OccupancyGrid
        return [x.logodds, np.asarray(x.origin_xy), np.asarray([x.resolution_m])]
    return [np.asarray(x)]


def same(a, b) -> bool:
    A, B = _arrays(a), _arrays(b)
    return len(A) == len(B) and all(
        x.shape == y.shape and np.array_equal(x, y, equal_nan=x.dtype.kind == "f") for x, y in zip(A, B)
    )


@dataclass
class Reader:
    name: str
    text: str  # the intact file
    suffix: str
    read: Callable
    lines: bool = True  # a line format: a cut keeps the intact lines before it
    compress: str | None = None  # "gz" | "zip"


def _read_map(path):
    (path.parent / "m.pgm").write_bytes(pgm_bytes())
    return load_map(path)


READERS = [
    Reader("carmen", carmen_text(), ".clf", read_carmen),
    Reader("carmen.gz", carmen_text(), ".clf.gz", read_carmen, compress="gz"),
    Reader("carmen_poses", carmen_text(), ".log", read_carmen_poses),
    Reader("tum", tum_text(), ".tum", read_tum),
    Reader("tum.gz", tum_text(), ".tum", read_tum, compress="gz"),
    Reader("matched_csv", csv_text(), ".csv", read_matched_csv),
    Reader("relations", relations_text(), ".relations", read_relations),
    Reader("splits", splits_text(), ".json", read_splits, lines=False),
    Reader("g2o", g2o_text(), ".g2o", read_g2o),
    Reader("g2o.zip", g2o_text(), ".zip", read_g2o, compress="zip"),
    Reader("map_yaml", map_yaml_text(), ".yaml", _read_map, lines=False),
]
BY_NAME = {r.name: r for r in READERS}


def encode(reader: Reader, text: bytes) -> bytes:
    if reader.compress == "gz":
        return gzip.compress(text, mtime=0)
    if reader.compress == "zip":
        buf = io.BytesIO()
        with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as z:
            z.writestr("graph.g2o", text)
        return buf.getvalue()
    return text


@dataclass
class Read:
    """One read of one file: its value, or its error, and the warnings it gave."""

    path: Path
    value: object = None
    error: Exception | None = None
    warnings: tuple = ()
    other_warnings: tuple = ()

    @property
    def loud(self) -> bool:
        return self.error is not None or bool(self.warnings)

    def unnamed(self) -> str | None:
        """What fails the rule that every error and warning names the file (and stays readable)."""
        if self.error is not None and (str(self.path) not in str(self.error) or len(str(self.error)) > 2000):
            return f"error without the file name or too long: {str(self.error)[:300]}"
        if any(str(self.path) not in w for w in self.warnings):
            return f"warning without the file name: {self.warnings}"
        if self.other_warnings:
            return f"other warnings: {self.other_warnings}"
        return None


EXPECTED = (LogFormatError, ValueError, FileNotFoundError)  # LogFormatError is a ValueError


def read(reader: Reader, path: Path, data: bytes) -> Read:
    """Write ``data`` to ``path`` and read it; an exception of a type no reader should raise propagates."""
    path.write_bytes(data)
    r = Read(path)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            r.value = reader.read(path)
        except EXPECTED as e:
            r.error = e
    r.warnings = tuple(str(w.message) for w in caught if issubclass(w.category, LogDefectWarning))
    r.other_warnings = tuple(str(w.message)[:200] for w in caught if not issubclass(w.category, LogDefectWarning))
    return r


# no number contains these: a byte turned into one of them can only be read wrong by a reader that skips it
GARBAGE = [b"x", b"\x00", b"\xff", b"\xc3(", b";", b",", b"{", b"]", b"nan", b"inf", b"?"]
# whitespace may also be inserted (it splits a token or a line: counts and record names tell); never replace
# a byte by it (a minus sign turned into a space is a silent wrong number: out of scope as digit flips are)
INSERTED = GARBAGE + [b" ", b"\t", b"\n"]
CLASSES = ("cut", "replaced", "inserted", "archive", "random")


def corrupt(reader: Reader, kind: str, pick) -> tuple[bytes, bytes | None, str]:
    """(corrupted file, the file whose read it must equal if read silently, a description). ``pick(n)``
    returns an integer in [0, n): hypothesis' draws in the tests, a seeded generator here."""
    raw = reader.text.encode()
    blob = encode(reader, raw)
    if kind == "cut":
        k = pick(len(blob))
        if reader.compress or not reader.lines:
            return blob[:k], blob, f"cut at {k}"
        whole = raw[:k][: raw[:k].rfind(b"\n") + 1]
        return blob[:k], whole, f"cut at {k}"
    if kind in ("replaced", "inserted"):
        junk_set = GARBAGE if kind == "replaced" else INSERTED
        pos, junk = pick(len(raw)), junk_set[pick(len(junk_set))]
        text = raw[:pos] + junk + raw[pos + (1 if kind == "replaced" else 0) :]
        return encode(reader, text), blob, f"{kind} {junk!r} at {pos}"
    if kind == "archive":
        flipped = bytearray(blob)
        pos = pick(len(blob))
        flipped[pos] ^= 1 + pick(255)
        return bytes(flipped), blob, f"byte {pos} flipped"
    if kind == "random":
        n = 1 + pick(300)
        return bytes(pick(256) for _ in range(n)), None, f"{n} random bytes"
    raise ValueError(f"corruption class {kind!r}: expected one of {CLASSES}")


def verdict(reader: Reader, folder: Path, kind: str, pick) -> tuple[str, str]:
    """(outcome, description) of one corrupted case: error | warning | intact | silent wrong | unexpected."""
    data, equal_to, what = corrupt(reader, kind, pick)
    try:
        got = read(reader, folder / f"case{reader.suffix}", data)
    except Exception as e:  # a type no reader should raise
        return "unexpected", f"{what}: {type(e).__name__}: {str(e)[:200]}"
    if (problem := got.unnamed()) is not None:
        return "unexpected", f"{what}: {problem}"
    if got.error is not None:
        return "error", what
    unfinished = kind == "cut" and reader.lines and not reader.compress and data[len(equal_to) :].strip() != b""
    if equal_to is None:
        return ("warning", what) if got.warnings else ("silent wrong", f"{what}: random bytes read as data")
    ref = read(reader, folder / f"ref{reader.suffix}", equal_to)
    if ref.error is not None:  # the intact lines alone are no valid file: nor may the cut one be
        return "silent wrong", f"{what}: read, although its intact lines alone are no file"
    if unfinished and not got.warnings:
        return "silent wrong", f"{what}: an unfinished last line went unreported"
    if same(got.value, ref.value):
        return ("warning", what) if got.warnings else ("intact", what)
    return ("warning", what) if got.warnings else ("silent wrong", f"{what}: read other values than the intact file")


def intact_read(reader: Reader, folder: Path):
    r = read(reader, folder / f"intact{reader.suffix}", encode(reader, reader.text.encode()))
    if r.error is not None or r.warnings or r.other_warnings:
        raise AssertionError(f"{reader.name}: the intact sample does not read cleanly: {r.error} {r.warnings}")
    return r.value


def classes_of(reader: Reader) -> list[str]:
    return [k for k in CLASSES if k != "archive" or reader.compress]


def run(cases: int, seed: int) -> dict:
    rng = np.random.default_rng(seed)
    table, examples = {}, {}
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        for reader in READERS:
            intact_read(reader, folder)
            for kind in classes_of(reader):
                counts = Counter()
                for _ in range(cases):
                    outcome, what = verdict(reader, folder, kind, lambda n: int(rng.integers(n)))
                    counts[outcome] += 1
                    if outcome in ("silent wrong", "unexpected"):
                        examples.setdefault(f"{reader.name}/{kind}", what)
                table[f"{reader.name}/{kind}"] = dict(counts)
    return {"cases_per_class": cases, "seed": seed, "outcomes": table, "failures": examples}


OUTCOMES = ("error", "warning", "intact", "silent wrong", "unexpected")


def markdown(result: dict) -> str:
    lines = [f"| reader | class | cases | {' | '.join(OUTCOMES)} |", "|---|---|" + "---|" * (1 + len(OUTCOMES))]
    total = Counter()
    for key, counts in result["outcomes"].items():
        reader, kind = key.split("/")
        n = sum(counts.values())
        total.update(counts)
        lines.append(f"| {reader} | {kind} | {n} | " + " | ".join(str(counts.get(o, 0)) for o in OUTCOMES) + " |")
    n = sum(total.values())
    lines.append(f"| **all** | | **{n}** | " + " | ".join(f"**{total.get(o, 0)}**" for o in OUTCOMES) + " |")
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(prog="python -m eval.analyses.fuzz")
    ap.add_argument("--cases", type=int, default=100, help="cases per reader and corruption class")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--write", action="store_true", help="write docs/reader-fuzz.md and results/readers/fuzz.json")
    args = ap.parse_args(argv)
    result = run(args.cases, args.seed)
    table = markdown(result)
    print(table)
    for key, what in result["failures"].items():
        print(f"FAILED {key}: {what}")
    if args.write:
        atomic_write_bytes(
            REPO / "results" / "readers" / "fuzz.json", (json.dumps(result, indent=1, sort_keys=True) + "\n").encode()
        )
        doc = (
            DOC_HEAD + f"\nMade by `python -m eval.analyses.fuzz --cases {args.cases} --seed {args.seed} --write` "
            f"(2-core CPU).\n\n" + table + "\n"
        )
        atomic_write_bytes(REPO / "docs" / "reader-fuzz.md", doc.encode())
    return 1 if result["failures"] else 0


DOC_HEAD = """# Readers against corrupted input

Every reader is held to one rule: a corrupted file is an error or a warning naming the file, or it reads
exactly as the intact file does. Never a silent wrong value, never another exception type. The classes,
what is out of scope and why, and how each outcome is judged are in `eval/fuzz.py`'s docstring;
`tests/test_fuzz_readers.py` runs the same classes through hypothesis in CI (40 examples per reader and
class; `IRMCL_FUZZ_EXAMPLES` for more) plus the cases issue 16 listed one by one.
"""


if __name__ == "__main__":
    raise SystemExit(guard(main))
