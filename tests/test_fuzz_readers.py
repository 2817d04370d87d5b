"""Every reader against corrupted input (issue 16's corruption classes, defined in eval/fuzz.py): a read either
fails with an error naming the file, or warns naming the file, or returns exactly what the intact file says.
Never a silent wrong value, never another exception type. hypothesis picks the positions and bytes; the
classes one by one as the issue listed them follow at the end."""

from __future__ import annotations

import gzip
import os
import warnings

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from eval.analyses.fuzz import (
    BY_NAME,
    READERS,
    carmen_text,
    classes_of,
    encode,
    g2o_text,
    intact_read,
    relations_text,
    same,
    verdict,
)
from irmcl_warp.io import LogDefectWarning, LogFormatError, read_carmen, read_g2o, read_relations, read_splits

FUZZ = settings(
    max_examples=int(os.environ.get("IRMCL_FUZZ_EXAMPLES", 40)),
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)
CASES = [(r, kind) for r in READERS for kind in classes_of(r)]


@pytest.mark.parametrize("reader", READERS, ids=lambda r: r.name)
def test_intact_files_read_without_a_word(reader, tmp_path):
    assert intact_read(reader, tmp_path) is not None


@pytest.mark.parametrize("reader, kind", CASES, ids=[f"{r.name}-{k}" for r, k in CASES])
@FUZZ
@given(data=st.data())
def test_a_corrupted_file_fails_or_warns_naming_it_or_reads_intact(reader, kind, tmp_path, data):
    outcome, what = verdict(reader, tmp_path, kind, lambda n: data.draw(st.integers(0, n - 1)))
    assert outcome in ("error", "warning", "intact"), f"{reader.name}: {outcome}: {what}"


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


@pytest.mark.parametrize(
    "reader, old, new, expected",
    [
        ("relations", "100.000000 102.500000", "100.000000 100.000000", "t1 = t2 = 100.000000: a relation joins two"),
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
    ],
)
def test_listed_corruptions_are_errors_naming_the_file_and_the_line(reader, old, new, expected, tmp_path):
    r = BY_NAME[reader]
    assert old in r.text, old
    p = _write(tmp_path, "bad" + r.suffix, r.text.replace(old, new, 1))
    with pytest.raises(ValueError, match=expected) as e:
        r.read(p)
    assert str(p) in str(e.value)


@pytest.mark.parametrize(
    "what, blob",
    [
        ("a cut gzip", gzip.compress(carmen_text().encode())[:-30]),
        ("gzip with a corrupt stream", gzip.compress(carmen_text().encode())[:20] + b"\x00" * 40),
        ("binary junk", bytes(range(256)) * 4),
    ],
)
@pytest.mark.parametrize("reader", ["carmen", "tum", "matched_csv", "relations", "g2o"])
def test_broken_compressed_and_binary_input_is_a_log_format_error(reader, what, blob, tmp_path):
    p = _write(tmp_path, "broken" + BY_NAME[reader].suffix, blob)
    with pytest.raises(LogFormatError) as e:
        BY_NAME[reader].read(p)
    assert str(p) in str(e.value) and len(str(e.value)) < 2000


def test_relations_whose_stamps_run_backwards_are_warned_about_and_kept(tmp_path):
    """intel's relations file holds 6 (its logger's clock steps back): each is still the motion t1 -> t2."""
    p = _write(
        tmp_path, "back.relations", relations_text().replace("100.000000 102.500000", "102.500000 100.000000", 1)
    )
    with pytest.warns(LogDefectWarning, match="1 relations whose t1 is later than t2"):
        rel = read_relations(p)
    assert (rel.t1[0], rel.t2[0]) == (102.5, 100.0) and len(rel) == 12


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
