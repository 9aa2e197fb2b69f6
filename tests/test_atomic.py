"""Atomic writes: a reader sees the old file or the new one; a failed write leaves the old file and no temporary."""

import os

import pytest

from peano_bayes import atomic


def test_write_text_replaces_and_keeps_the_permission_bits(tmp_path):
    target = tmp_path / "a.json"
    atomic.write_text(target, "first\n")
    os.chmod(target, 0o640)
    atomic.write_text(target, "second ü\n")
    assert target.read_text(encoding="utf-8") == "second ü\n"
    assert target.stat().st_mode & 0o777 == 0o640
    assert os.listdir(tmp_path) == ["a.json"]


def test_a_failed_write_leaves_the_old_file_and_no_temporary(tmp_path):
    target = tmp_path / "a.bin"
    atomic.write_bytes(target, b"old")
    with pytest.raises(RuntimeError), atomic.replacing(target) as tmp:
        tmp.write_bytes(b"half")
        raise RuntimeError("interrupted")
    assert target.read_bytes() == b"old" and os.listdir(tmp_path) == ["a.bin"]
