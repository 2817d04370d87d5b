"""Ground truth and evaluation files: matched corrected poses (CSV), Kümmerle relations, benchmark splits,
g2o files (VERTEX_SE2 + ROBOTLASER1). All matching across files is by stamp."""

from __future__ import annotations

import json
import re
import warnings
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from irmcl_warp.io.atomic import atomic_write_bytes
from irmcl_warp.io.carmen import _count, _parse_robotlaser
from irmcl_warp.io.errors import LogDefectWarning, LogFormatError, check_pose_stamps
from irmcl_warp.io.text import check_comment, decode_lines, parse_floats, read_lines

MAX_PLAUSIBLE_MOTION_M = 1.0e4  # a relation or pose farther than this is corrupt
MAX_SPLIT_STEP_BACK_S = 0.5  # split stamps follow the log's time; intel's logger steps back by < 0.13 s


def _content_lines(path, numbered=None):
    """Numbered lines of a text file, comments and blank lines left out; an unfinished last line (the file
    was cut off while written, and its last number may be cut too) dropped with a warning."""
    lines, cut = read_lines(path) if numbered is None else numbered
    if cut:
        warnings.warn(
            f"{path}: unfinished last line {lines[-1][0]} dropped (the file ends without a newline: "
            f"cut off while written?)",
            LogDefectWarning,
            stacklevel=3,
        )
        lines = lines[:-1]
    out = []
    for n, ln in lines:
        ln = ln.strip()
        if ln.startswith("#"):
            check_comment(path, n, ln)
        elif ln:
            out.append((n, ln))
    return out


def read_matched_csv(path) -> tuple[np.ndarray, np.ndarray]:
    """``corrected/matched/<name>.gmapping_corrected_keyframes.csv`` -> (ipc stamps[N], poses[N, 3]).

    Columns ``bag_scan_index,ipc_stamp,x,y,theta``; lines starting with '#' are comments.
    """
    path = Path(path)
    rows, lines, header_seen = [], [], False
    for n_line, line in _content_lines(path):
        if not header_seen:
            cols = [c.strip() for c in line.split(",")]
            if cols[:5] != ["bag_scan_index", "ipc_stamp", "x", "y", "theta"]:
                raise LogFormatError(
                    path, f"line {n_line}", f"expected header bag_scan_index,ipc_stamp,x,y,theta, found {line[:80]!r}"
                )
            header_seen = True
            continue
        tok = line.split(",")
        if len(tok) != 5:
            raise LogFormatError(path, f"line {n_line}", f"expected 5 comma-separated values, found {len(tok)}")
        row = parse_floats(path, n_line, tok, "matched pose")
        _check_pose(path, n_line, row[2:5])
        rows.append(row)
        lines.append(n_line)
    if not rows:
        raise LogFormatError(path, None, "no poses (empty file or header only)")
    a = np.array(rows)
    return check_pose_stamps(path, a[:, 1], a[:, 2:5], lines)


def _check_pose(path, n_line, pose, what="pose"):
    x, y, yaw = pose
    if max(abs(x), abs(y)) > MAX_PLAUSIBLE_MOTION_M:
        raise LogFormatError(
            path,
            f"line {n_line}",
            f"{what} ({x:g}, {y:g}) is more than {MAX_PLAUSIBLE_MOTION_M:g} m away: expected metres",
        )
    if abs(yaw) > MAX_PLAUSIBLE_MOTION_M:  # unwrapped headings are fine (mit-csail's keyframes reach 6.6 rad)
        raise LogFormatError(path, f"line {n_line}", f"{what} yaw {yaw:g}: expected radians")


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
    rows, lines = [], []
    for n_line, line in _content_lines(path):
        tok = line.split()
        if len(tok) != 8:
            raise LogFormatError(
                path, f"line {n_line}", f"expected 8 values (stamp x y z qx qy qz qw), found {len(tok)}"
            )
        t, x, y, _, qx, qy, qz, qw = parse_floats(path, n_line, tok, "TUM pose")
        norm = float(np.sqrt(qx * qx + qy * qy + qz * qz + qw * qw))
        if abs(norm - 1.0) > 1e-2:  # printed to a few decimals a unit quaternion stays within 1e-3 of 1
            raise LogFormatError(
                path,
                f"line {n_line}",
                f"quaternion ({qx}, {qy}, {qz}, {qw}) has length {norm:.4g}: expected a unit quaternion",
            )
        if abs(qx) > 1e-3 or abs(qy) > 1e-3:
            raise LogFormatError(
                path, f"line {n_line}", f"a 2D pose needs a rotation about z, found q = ({qx}, {qy}, {qz}, {qw})"
            )
        _check_pose(path, n_line, (x, y, 0.0))
        rows.append((t, x, y, 2.0 * np.arctan2(qz, qw)))
        lines.append(n_line)
    if not rows:
        raise LogFormatError(path, None, "no poses (empty file or comments only)")
    a = np.array(rows)
    return check_pose_stamps(
        path, a[:, 0], np.column_stack([a[:, 1:3], (a[:, 3] + np.pi) % (2 * np.pi) - np.pi]), lines
    )


def write_tum(path, stamps, poses) -> None:
    """Poses [N, 3] (x, y, yaw) at ``stamps`` as a TUM trajectory (``read_tum``'s format), written atomically.
    A pose that is not finite (no estimate yet) has no line, as evo expects."""
    lines = [
        f"{t:.6f} {x:.6f} {y:.6f} 0 0 0 {np.sin(a / 2):.9f} {np.cos(a / 2):.9f}"
        for t, (x, y, a) in zip(stamps, poses)
        if np.isfinite(x) and np.isfinite(y) and np.isfinite(a)
    ]
    atomic_write_bytes(Path(path), ("\n".join(lines) + "\n").encode())


def read_relations(path) -> Relations:
    """``t1 t2 x y z roll pitch yaw`` per line: the motion from the pose stamped t1 to the one stamped t2
    (t1 != t2; t1 > t2 is warned about: intel's logger stamps step back; yaw in radians within [-pi, pi])."""
    path = Path(path)
    rows, backwards = [], 0
    for n_line, line in _content_lines(path):
        tok = line.split()
        if len(tok) != 8:
            raise LogFormatError(
                path, f"line {n_line}", f"expected 8 values 't1 t2 x y z roll pitch yaw', found {len(tok)}"
            )
        row = parse_floats(path, n_line, tok, "relation")
        if row[0] == row[1]:
            raise LogFormatError(path, f"line {n_line}", f"t1 = t2 = {row[0]:.6f}: a relation joins two scans")
        backwards += int(row[0] > row[1])
        if abs(row[7]) > np.pi + 1e-6 or max(abs(row[2]), abs(row[3])) > MAX_PLAUSIBLE_MOTION_M:
            raise LogFormatError(
                path,
                f"line {n_line}",
                f"motion ({row[2]:g}, {row[3]:g}, yaw {row[7]:g}): expected "
                f"metres and a yaw in radians within [-pi, pi]",
            )
        rows.append(row)
    if not rows:
        raise LogFormatError(path, None, "no relations")
    a = np.array(rows)
    if backwards:  # intel's: its logger's stamps step back (../shared/data/README.md); the motion is still t1 -> t2
        warnings.warn(
            f"{path}: {backwards} relations whose t1 is later than t2 (a log whose clock steps back?); "
            f"each is scored as the motion from the scan stamped t1 to the one stamped t2",
            LogDefectWarning,
            stacklevel=2,
        )
    pairs = np.unique(a[:, :2], axis=0, return_counts=True)[1]
    if (pairs > 1).any():
        warnings.warn(
            f"{path}: {int((pairs > 1).sum())} relations given more than once (each is scored as often)",
            LogDefectWarning,
            stacklevel=2,
        )
    return Relations(a[:, 0], a[:, 1], a[:, [2, 3, 7]])


def read_splits(path) -> dict[str, np.ndarray]:
    """``splits/<name>.json`` -> {split name: stamps}, for train/val/test and their *_block variants."""
    path = Path(path)
    try:
        d = json.loads(path.read_bytes().decode("utf-8"))
    except UnicodeDecodeError as e:
        raise LogFormatError(path, None, f"not UTF-8 text (byte {e.start}): expected a JSON file") from e
    except json.JSONDecodeError as e:
        raise LogFormatError(path, f"line {e.lineno}", f"invalid JSON: {e.msg}") from e
    if not isinstance(d, dict):
        raise LogFormatError(path, None, f"expected a JSON object of split name -> stamps, found {type(d).__name__}")
    out = {}
    names = {f"{s}{b}" for s in ("train", "val", "test") for b in ("", "_block")}
    odd = sorted(k for k, v in d.items() if isinstance(v, list) and k not in names)
    if odd:
        warnings.warn(
            f"{path}: lists of unknown split names {odd[:5]} (expected {sorted(names)})", LogDefectWarning, stacklevel=2
        )
    for k, v in d.items():
        if not isinstance(v, list) or k not in names:
            continue
        bad = [x for x in v if isinstance(x, bool) or not isinstance(x, (int, float)) or not np.isfinite(x)]
        if bad:
            raise LogFormatError(path, f"split {k!r}", f"{len(bad)} entries are not finite stamps (first: {bad[0]!r})")
        stamps = np.asarray(v, dtype=np.float64)
        back = np.flatnonzero(np.diff(stamps) < -MAX_SPLIT_STEP_BACK_S)
        if back.size:
            i = int(back[0])
            raise LogFormatError(
                path,
                f"split {k!r}",
                f"stamp {stamps[i + 1]!r} (entry {i + 1}) lies "
                f"{stamps[i] - stamps[i + 1]:g} s before the one listed before it: expected stamps in "
                f"time order",
            )
        gaps = np.diff(stamps)
        if gaps.size > 2:
            limit = max(60.0, 100.0 * float(np.median(np.abs(gaps))))
            if (gaps > limit).any():
                i = int(np.argmax(gaps > limit))
                raise LogFormatError(
                    path,
                    f"split {k!r}",
                    f"stamps jump from {stamps[i]!r} to {stamps[i + 1]!r} (entry "
                    f"{i + 1}), {gaps[i]:g} s where they are {np.median(np.abs(gaps)):g} s apart "
                    f"otherwise: expected the stamps of one log (a number split in two?)",
                )
        if len(np.unique(stamps)) != len(stamps):
            raise LogFormatError(path, f"split {k!r}", f"{len(stamps) - len(np.unique(stamps))} stamps listed twice")
        out[k] = stamps
    for need in ("train", "val", "test"):
        if need not in out or len(out[need]) == 0:
            raise LogFormatError(path, None, f"split {need!r} missing or empty (found {sorted(out)})")
    return out


G2O_RECORD = re.compile(r"[A-Z][A-Z0-9_:]{1,39}")
# g2o's 2D types besides the ones read here: skipped without a word
G2O_KNOWN = {
    "VERTEX_XY",
    "EDGE_SE2_XY",
    "EDGE_PRIOR_SE2",
    "EDGE_SE2_PRIOR",
    "FIX",
    "PARAMS_SE2OFFSET",
    "VERTEX_SE2_TAG",
    "EDGE_SE2_OFFSET",
    "EDGE_SE2_POINTXY",
}


@dataclass
class G2oGraph:
    vertex_ids: np.ndarray
    vertex_poses: np.ndarray  # [V, 3]
    edges: np.ndarray  # [E, 5]: id_from, id_to, x, y, yaw
    laser_stamps: np.ndarray  # [V] true stamps of the ROBOTLASER1 attached to each vertex, in file order
    laser_ranges: list = None  # [V] range arrays of those ROBOTLASER1 lines
    laser_range_max_m: float = float("nan")


def read_g2o(path, member: str | None = None) -> G2oGraph:
    """g2o file with VERTEX_SE2, EDGE_SE2 and ROBOTLASER1 (plain, .gz, or the one .g2o in a .zip)."""
    path = Path(path)
    if zipfile.is_zipfile(path):
        try:
            with zipfile.ZipFile(path) as z:
                names = [n for n in z.namelist() if n.endswith(".g2o") and not n.startswith("__MACOSX")]
                if not names:
                    raise LogFormatError(path, None, f"zip holds no .g2o file (has {z.namelist()[:5]})")
                if member is not None and member not in z.namelist():
                    raise LogFormatError(path, None, f"zip holds no {member!r} (its .g2o files: {names[:5]})")
                numbered = decode_lines(path, z.read(member or names[0]))
        except LogFormatError:
            raise
        except Exception as e:  # zipfile raises many types for a damaged archive (BadZipFile, zlib.error, EOFError,
            #                     RuntimeError for a flag misread as encryption, NotImplementedError, ...)
            raise LogFormatError(path, None, f"cannot read the zip (truncated or corrupt?): {e}") from e
    else:
        numbered = None
    vid, vline, vpose, edges, eline, stamps, ranges, range_max = [], [], [], [], [], [], [], float("nan")
    unknown: dict[str, int] = {}
    for n_line, line in _content_lines(path, numbered):
        tok = line.split()
        if tok[0] == "VERTEX_SE2":
            if len(tok) != 5:
                raise LogFormatError(
                    path, f"line {n_line}", f"VERTEX_SE2: expected 'id x y theta', found {len(tok) - 1} values"
                )
            vid.append(_count(path, n_line, tok[1], "VERTEX_SE2 id"))
            v = parse_floats(path, n_line, tok[2:5], "VERTEX_SE2")
            _check_pose(path, n_line, v, "vertex")
            vpose.append(v)
            vline.append(n_line)
        elif tok[0] == "EDGE_SE2":
            if len(tok) not in (6, 12):
                raise LogFormatError(
                    path,
                    f"line {n_line}",
                    f"EDGE_SE2: expected 'from to x y theta' and optionally "
                    f"the 6 values of the information matrix, found {len(tok) - 1} values",
                )
            parse_floats(path, n_line, tok[6:], "EDGE_SE2 information")
            ids = [_count(path, n_line, t, "EDGE_SE2 vertex id") for t in tok[1:3]]
            motion = parse_floats(path, n_line, tok[3:6], "EDGE_SE2")
            _check_pose(path, n_line, motion, "edge motion")
            edges.append([*ids, *motion])
            eline.append(n_line)
        elif tok[0] == "ROBOTLASER1":
            scan = _parse_robotlaser(path, n_line, tok)
            stamps.append(scan.stamp)
            ranges.append(np.asarray(scan.ranges, np.float64))
            range_max = scan.range_max
        elif not G2O_RECORD.fullmatch(tok[0]):
            raise LogFormatError(
                path,
                f"line {n_line}",
                f"expected a record name (VERTEX_SE2, EDGE_SE2, ...), found {tok[0][:40]!r}: a line broken in two?",
            )
        elif tok[0] not in G2O_KNOWN:
            unknown[tok[0]] = unknown.get(tok[0], 0) + 1
    if unknown:
        kinds = ", ".join(f"{k!r} x{n}" for k, n in sorted(unknown.items(), key=lambda kv: -kv[1])[:5])
        warnings.warn(f"{path}: lines of unknown kinds skipped ({kinds})", LogDefectWarning, stacklevel=2)
    if not vid:
        raise LogFormatError(path, None, "no VERTEX_SE2 lines")
    seen = {}
    for i, n_line in zip(vid, vline):
        if i in seen:
            raise LogFormatError(path, f"line {n_line}", f"vertex {i} was defined at line {seen[i]} already")
        seen[i] = n_line
    for e, n_line in zip(edges, eline):
        missing = [int(i) for i in e[:2] if int(i) not in seen]
        if missing:
            raise LogFormatError(path, f"line {n_line}", f"edge to vertex {missing[0]}, which no VERTEX_SE2 defines")
    edges = np.array(edges, np.float64).reshape(-1, 5)
    repeated = len(edges) - len(np.unique(edges, axis=0))
    if repeated:
        warnings.warn(f"{path}: {repeated} EDGE_SE2 lines repeat another exactly", LogDefectWarning, stacklevel=2)
    return G2oGraph(np.array(vid), np.array(vpose), edges, np.array(stamps), ranges, range_max)


def g2o_scan_stamps(graph: G2oGraph, ranges_m: np.ndarray, decimals: int = 2) -> np.ndarray:
    """True stamps for a log whose own stamps are not (MIT Killian's bag): the stamp of the g2o laser with
    the same range array, NaN for scans that are no g2o keyframe. Ranges are compared at the g2o file's
    printed precision, with every reading at or beyond its maximum range (or missing) as "no echo"."""
    cutoff = graph.laser_range_max_m - 0.5 * 10.0**-decimals

    def key(r) -> bytes:
        r = np.asarray(r, np.float64)
        q = np.where(np.isfinite(r) & (r < cutoff), np.round(r * 10**decimals), -1).astype(np.int64)
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
