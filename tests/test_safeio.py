"""hystid.safeio: outputs kept apart, and folders written all or none."""

import os
import stat

import pytest

from hystid.safeio import OutputError, atomic_folder, check_apart, check_output, inside


def listing(folder):
    """Names and contents of every entry directly in ``folder``, hidden ones included."""
    return {p.name: p.read_text() for p in sorted(folder.iterdir())}


def test_atomic_folder_replaces_the_files_once_all_are_written(tmp_path):
    out = tmp_path / "report"
    out.mkdir()
    (out / "a.txt").write_text("old a")
    (out / "keep.txt").write_text("not written by the block")
    with atomic_folder(out) as stage:
        (stage / "a.txt").write_text("new a")
        (stage / "b.txt").write_text("new b")
        assert (out / "a.txt").read_text() == "old a"  # nothing moved before the block ends
    assert listing(out) == {"a.txt": "new a", "b.txt": "new b",
                            "keep.txt": "not written by the block"}


def test_atomic_folder_failing_midway_leaves_every_previous_file(tmp_path):
    out = tmp_path / "report"
    out.mkdir()
    (out / "a.txt").write_text("old a")
    (out / "b.txt").write_text("old b")
    with pytest.raises(OSError, match="disk full"), atomic_folder(out) as stage:
        (stage / "a.txt").write_text("new a")
        raise OSError("disk full")
    assert listing(out) == {"a.txt": "old a", "b.txt": "old b"}  # no staging folder left


def test_atomic_folder_makes_a_new_folder_appear_complete_or_not_at_all(tmp_path):
    out = tmp_path / "deep" / "report"
    with pytest.raises(KeyboardInterrupt), atomic_folder(out) as stage:
        (stage / "a.txt").write_text("half")
        raise KeyboardInterrupt
    assert not out.exists() and list((tmp_path / "deep").iterdir()) == []
    with atomic_folder(out) as stage:
        (stage / "a.txt").write_text("whole")
    assert listing(out) == {"a.txt": "whole"}
    mask = os.umask(0)
    os.umask(mask)
    assert stat.S_IMODE(out.stat().st_mode) == 0o777 & ~mask  # not the staging folder's 0700
    assert stat.S_IMODE((out / "a.txt").stat().st_mode) == 0o666 & ~mask


@pytest.mark.parametrize("name", ["report.json", "./report.json", "../report/model.json", ""])
def test_check_apart_refuses_the_folder_and_its_files(tmp_path, name):
    out = tmp_path / "report"
    with pytest.raises(OutputError, match="--history") as info:
        check_apart(out / name if name else out, out, ("report.json", "model.json"),
                    option="--history")
    assert "--out" in str(info.value)
    check_apart(out / "history.csv", out, ("report.json", "model.json"), option="--history")


def test_a_file_may_go_into_a_folder_yet_to_be_made_only_when_allowed(tmp_path):
    path = tmp_path / "new" / "h.csv"
    with pytest.raises(OutputError, match="does not exist"):
        check_output(path, option="--history")
    assert check_output(path, option="--history", create_folder=True) == path
    assert inside(path, tmp_path / "new") and inside(path, tmp_path)
    assert not inside(tmp_path / "newer" / "h.csv", tmp_path / "new")
