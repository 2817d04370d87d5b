"""Ground truth and evaluation files: matched corrected poses (CSV), Kümmerle relations, benchmark splits,
g2o files (VERTEX_SE2 + ROBOTLASER1). All matching across files is by stamp."""

from __future__ import annotations

import json
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from irmcl_warp.io.atomic import atomic_write_bytes
from irmcl_warp.io.carmen import _floats, _parse_robotlaser, open_text
from irmcl_warp.io.errors import LogFormatError


def read_matched_csv(path) -> tuple[np.ndarray, np.ndarray]:
    """``corrected/matched/<name>.gmapping_corrected_keyframes.csv`` -> (ipc stamps[N], poses[N, 3]).

    Columns ``bag_scan_index,ipc_stamp,x,y,theta``; lines starting with '#' are comments.
    """
    path = Path(path)
    rows, header_seen = [], False
    with open_text(path) as f:
        for n_line, line in enumerate(f, start=1):
            line = line.strip()
            if not line or line.startswith("#"):
                continue
            if not header_seen:
                cols = [c.strip() for c in line.split(",")]
                if cols[:5] != ["bag_scan_index", "ipc_stamp", "x", "y", "theta"]:
                    raise LogFormatError(path, f"line {n_line}", f"expected header bag_scan_index,ipc_stamp,x,y,theta, found {line!r}")
                header_seen = True
                continue
            tok = line.split(",")
            if len(tok) != 5:
                raise LogFormatError(path, f"line {n_line}", f"expected 5 comma-separated values, found {len(tok)}")
            rows.append(_floats(path, n_line, tok, "matched pose"))
    if not rows:
        raise LogFormatError(path, None, "no poses (empty file or header only)")
    a = np.array(rows)
    return a[:, 1], a[:, 2:5]


@dataclass
class Relations:
    """Kümmerle et al. 2009 relations: the motion ``T_i_j`` (x, y, yaw) between the poses stamped t1, t2."""

    t1: np.ndarray
    t2: np.ndarray
    motion: np.ndarray  # [R, 3]

    def __len__(self):
        return len(self.t1)


def read_tum(path) -> tuple[np.ndarray, np.ndarray]:
    """A TUM trajectory (evo's format: ``stamp x y z qx qy qz qw`` per line, '#' comments) -> (stamps[N],
    poses[N, 3]); the yaw is taken from the quaternion, which must be a rotation about z."""
    path = Path(path)
    rows = []
    with open_text(path) as f:
        for n_line, line in enumerate(f, start=1):
            line = line.strip()
            if not line or line.startswith("#"):
                continue
            tok = line.split()
            if len(tok) != 8:
                raise LogFormatError(path, f"line {n_line}", f"expected 8 values (stamp x y z qx qy qz qw), found {len(tok)}")
            t, x, y, _, qx, qy, qz, qw = _floats(path, n_line, tok, "TUM pose")
            if abs(qx) > 1e-3 or abs(qy) > 1e-3:
                raise LogFormatError(path, f"line {n_line}", f"a 2D pose needs a rotation about z, found q = ({qx}, {qy}, {qz}, {qw})")
            rows.append((t, x, y, 2.0 * np.arctan2(qz, qw)))
    if not rows:
        raise LogFormatError(path, None, "no poses (empty file or comments only)")
    a = np.array(rows)
    return a[:, 0], np.column_stack([a[:, 1:3], (a[:, 3] + np.pi) % (2 * np.pi) - np.pi])


def write_tum(path, stamps, poses) -> None:
    """Poses [N, 3] (x, y, yaw) at ``stamps`` as a TUM trajectory (``read_tum``'s format), written atomically."""
    lines = [f"{t:.6f} {x:.4f} {y:.4f} 0 0 0 {np.sin(a / 2):.6f} {np.cos(a / 2):.6f}" for t, (x, y, a) in zip(stamps, poses)]
    atomic_write_bytes(Path(path), ("\n".join(lines) + "\n").encode())


def read_relations(path) -> Relations:
    """``t1 t2 x y z roll pitch yaw`` per line."""
    path = Path(path)
    rows = []
    with open_text(path) as f:
        for n_line, line in enumerate(f, start=1):
            tok = line.split()
            if not tok or tok[0].startswith("#"):
                continue
            if len(tok) != 8:
                raise LogFormatError(path, f"line {n_line}", f"expected 8 values 't1 t2 x y z roll pitch yaw', found {len(tok)}")
            rows.append(_floats(path, n_line, tok, "relation"))
    if not rows:
        raise LogFormatError(path, None, "no relations")
    a = np.array(rows)
    return Relations(a[:, 0], a[:, 1], a[:, [2, 3, 7]])


def read_splits(path) -> dict[str, np.ndarray]:
    """``splits/<name>.json`` -> {split name: stamps}, for train/val/test and their *_block variants."""
    path = Path(path)
    try:
        d = json.loads(Path(path).read_text())
    except json.JSONDecodeError as e:
        raise LogFormatError(path, f"line {e.lineno}", f"invalid JSON: {e.msg}") from e
    out = {k: np.asarray(v, dtype=np.float64) for k, v in d.items() if isinstance(v, list)}
    for need in ("train", "val", "test"):
        if need not in out or len(out[need]) == 0:
            raise LogFormatError(path, None, f"split {need!r} missing or empty (found {sorted(out)})")
    return out


@dataclass
class G2oGraph:
    vertex_ids: np.ndarray
    vertex_poses: np.ndarray  # [V, 3]
    edges: np.ndarray  # [E, 5]: id_from, id_to, x, y, yaw
    laser_stamps: np.ndarray  # [V] true stamps of the ROBOTLASER1 attached to each vertex, in file order
    laser_ranges: list = None  # [V] range arrays of those ROBOTLASER1 lines
    laser_max_range_m: float = float("nan")


def read_g2o(path, member: str | None = None) -> G2oGraph:
    """g2o file with VERTEX_SE2, EDGE_SE2 and ROBOTLASER1 (plain, .gz, or the one .g2o in a .zip)."""
    path = Path(path)
    if zipfile.is_zipfile(path):
        with zipfile.ZipFile(path) as z:
            names = [n for n in z.namelist() if n.endswith(".g2o") and not n.startswith("__MACOSX")]
            if not names:
                raise LogFormatError(path, None, "zip holds no .g2o file")
            lines = z.read(member or names[0]).decode("utf-8", "replace").splitlines()
    else:
        with open_text(path) as f:
            lines = f.read().splitlines()
    vid, vpose, edges, stamps, ranges, max_range = [], [], [], [], [], float("nan")
    for n_line, line in enumerate(lines, start=1):
        tok = line.split()
        if not tok or tok[0].startswith("#"):
            continue
        if tok[0] == "VERTEX_SE2":
            if len(tok) < 5:
                raise LogFormatError(path, f"line {n_line}", "VERTEX_SE2: expected 'id x y theta'")
            v = _floats(path, n_line, tok[1:5], "VERTEX_SE2")
            vid.append(int(v[0]))
            vpose.append(v[1:4])
        elif tok[0] == "EDGE_SE2":
            if len(tok) < 6:
                raise LogFormatError(path, f"line {n_line}", "EDGE_SE2: expected 'from to x y theta [information]'")
            edges.append(_floats(path, n_line, tok[1:6], "EDGE_SE2"))
        elif tok[0] == "ROBOTLASER1":
            scan = _parse_robotlaser(path, n_line, tok)
            stamps.append(scan.stamp)
            ranges.append(np.asarray(scan.ranges, np.float64))
            max_range = scan.max_range
    if not vid:
        raise LogFormatError(path, None, "no VERTEX_SE2 lines")
    return G2oGraph(np.array(vid), np.array(vpose), np.array(edges).reshape(-1, 5), np.array(stamps), ranges,
                    max_range)


def g2o_scan_stamps(graph: G2oGraph, ranges_m: np.ndarray, decimals: int = 2) -> np.ndarray:
    """True stamps for a log whose own stamps are not (MIT Killian's bag): the stamp of the g2o laser with
    the same range array, NaN for scans that are no g2o keyframe. Ranges are compared at the g2o file's
    printed precision, with every reading at or beyond its maximum range (or missing) as "no echo"."""
    far = graph.laser_max_range_m - 0.5 * 10.0 ** -decimals

    def key(r) -> bytes:
        r = np.asarray(r, np.float64)
        q = np.where(np.isfinite(r) & (r < far), np.round(r * 10 ** decimals), -1).astype(np.int64)
        return q.tobytes()

    index = {}
    for k, r in enumerate(ranges_m):
        index.setdefault(key(r), k)
    out = np.full(len(ranges_m), np.nan)
    for stamp, r in zip(graph.laser_stamps, graph.laser_ranges):
        k = index.get(key(r))
        if k is not None:
            out[k] = stamp
    return out
