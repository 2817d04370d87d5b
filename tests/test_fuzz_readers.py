"""Every reader against corrupted input (issue 16's corruption classes): a read either fails with an error
naming the file, or warns naming the file, or returns exactly what the intact file says. Never a silent wrong
value, never another exception type.

The corruptions a reader can tell (a text reader has no checksum, so a digit turned into another digit is
out of scope): the file cut anywhere (then the intact lines before the cut must come back, and an unfinished
last line must be dropped loudly), a byte replaced by or inserted as a character that no number contains,
compressed files cut or corrupted, and the classes the issue lists one by one (at the end).
"""

from __future__ import annotations

import gzip
import io
import os
import json
import warnings
import zipfile
from dataclasses import dataclass
from typing import Callable

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from irmcl_warp.io import (LogDefectWarning, LogFormatError, read_carmen, read_carmen_poses, read_g2o, read_matched_csv,
                           read_relations, read_splits, read_tum)
from irmcl_warp.mapping.mapio import load_map

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
        for k in range(n))


def csv_text(n=12):
    return "bag_scan_index,ipc_stamp,x,y,theta\n" + "".join(
        f"{3 * k},{500 + 0.4 * k:.6f},{0.5 * k:.4f},{-1.5 + 0.1 * k:.4f},{-0.3 + 0.05 * k:.4f}\n" for k in range(n))


def relations_text(n=12):
    return "".join(f"{100 + k:.6f} {102.5 + k:.6f} {0.4 + 0.01 * k:.6f} {-0.2:.6f} 0 0 0 {0.1 - 0.02 * k:.6f}\n"
                   for k in range(n))


def splits_text():
    stamps = [round(100 + 0.2 * k, 6) for k in range(30)]
    return json.dumps({"source": "fuzz", "train": stamps[:20], "val": stamps[20:25], "test": stamps[25:],
                       "test_block": stamps[24:]}, indent=1) + "\n"


def g2o_text(n=6):
    lines = ["# g2o\n"]
    for k in range(n):
        lines.append(f"VERTEX_SE2 {k} {0.5 * k:.4f} {0.1 * k:.4f} {0.05 * k:.4f}\n")
    for k in range(n - 1):
        lines.append(f"EDGE_SE2 {k} {k + 1} 0.5000 0.1000 0.0500 100 0 0 100 0 1000\n")
    for k in range(n):
        r = " ".join(f"{2 + 0.1 * b:.2f}" for b in range(5))
        lines.append(f"ROBOTLASER1 0 -1.5708 3.1416 0.7854 50 0.01 0 5 {r} 0 0 0 0 0 0 0 0 0 0 0 0 "
                     f"{200 + k:.6f} host {200 + k:.6f}\n")
    return "".join(lines)


def map_yaml_text():
    return ("image: m.pgm\nresolution: 0.05\norigin: [-1.5, -2.25, 0.0]\nnegate: 0\noccupied_thresh: 0.65\n"
            "free_thresh: 0.196\nmode: trinary\n")


def pgm_bytes():
    img = np.full((6, 8), 254, np.uint8)
    img[2, 3:6] = 0
    img[4, 1] = 205
    return b"P5\n# a comment\n8 6\n255\n" + img.tobytes()


# ---------------------------------------------------------------- what a read returns, comparably


def _arrays(x):
    if isinstance(x, tuple):
        return [a for item in x for a in _arrays(item)]
    if isinstance(x, dict):
        return [np.asarray(sorted(x))] + [np.asarray(x[k]) for k in sorted(x)]
    if hasattr(x, "ranges_m"):  # LaserLog
        return [x.stamps, x.ranges_m, x.odom, np.asarray(x.info.angles_rad), np.asarray([x.info.no_return_m]),
                x.T_base_laser]
    if hasattr(x, "motion"):  # Relations
        return [x.t1, x.t2, x.motion]
    if hasattr(x, "vertex_ids"):  # G2oGraph
        return [x.vertex_ids, x.vertex_poses, x.edges, x.laser_stamps, *x.laser_ranges]
    if hasattr(x, "logodds"):  # OccupancyGrid
        return [x.logodds, np.asarray(x.origin_xy), np.asarray([x.resolution_m])]
    return [np.asarray(x)]


def same(a, b) -> bool:
    A, B = _arrays(a), _arrays(b)
    return len(A) == len(B) and all(x.shape == y.shape and np.array_equal(x, y, equal_nan=x.dtype.kind == "f")
                                    for x, y in zip(A, B))


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


class Outcome:
    def __init__(self, reader: Reader, path, data: bytes):
        path.write_bytes(data)
        self.path, self.error, self.value = path, None, None
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            try:
                self.value = reader.read(path)
            except (LogFormatError, ValueError, FileNotFoundError) as e:  # LogFormatError is a ValueError
                self.error = e
        self.warnings = [str(w.message) for w in caught if issubclass(w.category, LogDefectWarning)]
        others = [w for w in caught if not issubclass(w.category, LogDefectWarning)]
        assert not others, f"{reader.name}: unexpected warnings {[str(w.message)[:200] for w in others]}"

    def loud(self) -> bool:
        """Failed or warned, naming the file."""
        if self.error is not None:
            assert str(self.path) in str(self.error), f"error without the file name: {self.error}"
            assert len(str(self.error)) < 2000, "an error message should stay readable"
            return True
        if self.warnings:
            assert all(str(self.path) in w for w in self.warnings), self.warnings
            return True
        return False


def intact(reader, tmp_path):
    o = Outcome(reader, tmp_path / f"intact{reader.suffix}", encode(reader, reader.text.encode()))
    assert o.error is None and not o.warnings, (reader.name, o.error, o.warnings)
    return o.value


@pytest.mark.parametrize("reader", READERS, ids=lambda r: r.name)
def test_intact_files_read_without_a_word(reader, tmp_path):
    assert intact(reader, tmp_path) is not None


# ---------------------------------------------------------------- corruptions

# no number contains these: a byte turned into one of them can only be read wrong by a reader that skips it
GARBAGE = [b"x", b"\x00", b"\xff", b"\xc3(", b";", b",", b"{", b"]", b"nan", b"inf", b"?"]
# whitespace may also be inserted (it splits a token or a line: counts and record names tell); never replace
# a byte by it (a minus sign turned into a space is a silent wrong number: out of scope as digit flips are)
INSERTED = GARBAGE + [b" ", b"\t", b"\n"]

FUZZ = settings(max_examples=int(os.environ.get("IRMCL_FUZZ_EXAMPLES", 40)), deadline=None, derandomize=True,
                suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])


@pytest.mark.parametrize("reader", READERS, ids=lambda r: r.name)
@FUZZ
@given(data=st.data())
def test_a_cut_file_fails_or_gives_back_its_intact_lines(reader, tmp_path, data):
    raw = reader.text.encode()
    blob = encode(reader, raw)
    cut = data.draw(st.integers(0, len(blob) - 1), label="cut")
    o = Outcome(reader, tmp_path / f"cut{reader.suffix}", blob[:cut])
    if reader.compress:  # a cut archive is an error, however little is missing
        assert o.error is not None, f"{reader.name}: a cut {reader.compress} file was read"
        o.loud()
        return
    if not reader.lines:
        assert o.loud() or same(o.value, intact(reader, tmp_path)), f"{reader.name}: cut at {cut} read silently"
        return
    whole_lines = raw[:cut][: raw[:cut].rfind(b"\n") + 1]
    unfinished = raw[:cut][len(whole_lines):].strip() != b""
    ref = Outcome(reader, tmp_path / f"lines{reader.suffix}", whole_lines)
    if ref.error is not None:  # the intact lines alone are no valid file (too few, no header): nor is the cut one
        assert o.error is not None, f"{reader.name}: cut at {cut} read although its intact lines are no file"
        o.loud()
        return
    if o.error is None:
        assert same(o.value, ref.value), f"{reader.name}: cut at {cut} read other values than its intact lines"
    if unfinished:
        assert o.loud(), f"{reader.name}: an unfinished last line (cut at {cut}) went unreported"


def _mutate(reader, data, replace: bool):
    raw = reader.text.encode()
    pos = data.draw(st.integers(0, len(raw) - 1), label="position")
    junk = data.draw(st.sampled_from(GARBAGE if replace else INSERTED), label="junk")
    return raw[:pos] + junk + raw[pos + (1 if replace else 0):], (pos, junk)


@pytest.mark.parametrize("reader", READERS, ids=lambda r: r.name)
@FUZZ
@given(data=st.data())
def test_a_replaced_byte_fails_warns_or_changes_nothing(reader, tmp_path, data):
    text, where = _mutate(reader, data, replace=True)
    o = Outcome(reader, tmp_path / f"bad{reader.suffix}", encode(reader, text))
    assert o.loud() or same(o.value, intact(reader, tmp_path)), f"{reader.name}: {where} read silently wrong"


@pytest.mark.parametrize("reader", READERS, ids=lambda r: r.name)
@FUZZ
@given(data=st.data())
def test_an_inserted_byte_fails_warns_or_changes_nothing(reader, tmp_path, data):
    text, where = _mutate(reader, data, replace=False)
    o = Outcome(reader, tmp_path / f"ins{reader.suffix}", encode(reader, text))
    assert o.loud() or same(o.value, intact(reader, tmp_path)), f"{reader.name}: {where} read silently wrong"


@pytest.mark.parametrize("reader", [r for r in READERS if r.compress], ids=lambda r: r.name)
@FUZZ
@given(data=st.data())
def test_a_corrupted_archive_fails_or_reads_intact(reader, tmp_path, data):
    blob = bytearray(encode(reader, reader.text.encode()))
    pos = data.draw(st.integers(0, len(blob) - 1), label="position")
    blob[pos] ^= data.draw(st.integers(1, 255), label="xor")
    o = Outcome(reader, tmp_path / f"flip{reader.suffix}", bytes(blob))
    assert o.loud() or same(o.value, intact(reader, tmp_path)), f"{reader.name}: byte {pos} flipped, read wrong"


@pytest.mark.parametrize("reader", READERS, ids=lambda r: r.name)
@FUZZ
@given(junk=st.binary(min_size=1, max_size=300))
def test_random_bytes_are_an_error_naming_the_file(reader, tmp_path, junk):
    o = Outcome(reader, tmp_path / f"junk{reader.suffix}", junk)
    assert o.error is not None or o.loud(), f"{reader.name}: random bytes read as data"


# ---------------------------------------------------------------- the classes issue 16 lists


def _write(tmp_path, name, text):
    p = tmp_path / name
    p.write_bytes(text if isinstance(text, bytes) else text.encode())
    return p


@pytest.mark.parametrize("reader", ["carmen", "tum", "matched_csv", "relations", "g2o"])
def test_a_last_line_cut_mid_number_is_dropped_loudly_never_kept(reader, tmp_path):
    r = BY_NAME[reader]
    text = r.text.rstrip("\n")
    cut = text[:-3]  # the last number loses its last three characters but the line keeps its field count
    with pytest.warns(LogDefectWarning, match="unfinished last line"):
        got = r.read(_write(tmp_path, "cut" + r.suffix, cut))
    whole = text[: text.rfind("\n") + 1]
    with warnings.catch_warnings():
        warnings.simplefilter("error", LogDefectWarning)
        assert same(got, r.read(_write(tmp_path, "whole" + r.suffix, whole)))


@pytest.mark.parametrize("reader, old, new, expected", [
    ("relations", "100.000000 102.500000", "102.500000 100.000000", "t1 102.500000 is not before t2"),
    ("relations", "0.100000\n", "1000000.0\n", r"yaw 1e\+06\): expected metres and a yaw in radians"),
    ("g2o", "VERTEX_SE2 3 ", "VERTEX_SE2 3.5 ", "VERTEX_SE2 id: expected a whole number"),
    ("g2o", "EDGE_SE2 4 5 ", "EDGE_SE2 4 9 ", "edge to vertex 9, which no VERTEX_SE2 defines"),
    ("g2o", "VERTEX_SE2 4 ", "VERTEX_SE2 3 ", "vertex 3 was defined at line 5 already"),
    ("carmen", "FLASER 7 ", "FLASER -5 ", "FLASER beam count: expected a whole number"),
    ("splits", '"test": [\n', '"test": [\n  NaN,\n', r"split 'test'.*not finite stamps"),
    ("splits", '"test": [\n', '"test": [\n  "104.0",\n', r"split 'test'.*not finite stamps"),
    ("tum", "0 0 0 0.000000 1.000000", "0 0 0 0 0", "has length 0: expected a unit quaternion"),
    ("map_yaml", "negate: 0", "negate: x0", "negate must be 0 or 1"),
    ("map_yaml", "mode: trinary", "mode: scale", "only map_server's trinary maps"),
])
def test_listed_corruptions_are_errors_naming_the_file_and_the_line(reader, old, new, expected, tmp_path):
    r = BY_NAME[reader]
    assert old in r.text, old
    p = _write(tmp_path, "bad" + r.suffix, r.text.replace(old, new, 1))
    with pytest.raises(ValueError, match=expected) as e:
        r.read(p)
    assert str(p) in str(e.value)


@pytest.mark.parametrize("what, blob", [
    ("a cut gzip", gzip.compress(carmen_text().encode())[:-30]),
    ("gzip with a corrupt stream", gzip.compress(carmen_text().encode())[:20] + b"\x00" * 40),
    ("binary junk", bytes(range(256)) * 4),
])
@pytest.mark.parametrize("reader", ["carmen", "tum", "matched_csv", "relations", "g2o"])
def test_broken_compressed_and_binary_input_is_a_log_format_error(reader, what, blob, tmp_path):
    p = _write(tmp_path, "broken" + BY_NAME[reader].suffix, blob)
    with pytest.raises(LogFormatError) as e:
        BY_NAME[reader].read(p)
    assert str(p) in str(e.value) and len(str(e.value)) < 2000


def test_broken_zip_and_json_are_log_format_errors(tmp_path):
    z = encode(BY_NAME["g2o.zip"], g2o_text().encode())
    for blob in (z[: len(z) - 10], z[:30] + b"\xff" * 60 + z[90:]):
        p = _write(tmp_path, "bad.zip", blob)
        with pytest.raises(LogFormatError, match="bad.zip"):
            read_g2o(p)
    for text in (b'{"train": [1, 2', b"\xff\xfe{}", b"[1, 2, 3]"):
        p = _write(tmp_path, "bad.json", text)
        with pytest.raises(LogFormatError, match="bad.json"):
            read_splits(p)


def test_a_message_for_an_unknown_format_is_capped(tmp_path):
    text = "".join(f"KIND{k} 1 2 3\n" for k in range(5000))
    p = _write(tmp_path, "other.log", text)
    with pytest.raises(LogFormatError) as e:
        read_carmen(p)
    assert "and 4995 other kinds" in str(e.value) and len(str(e.value)) < 600
