"""Outputs appear together or not at all (mitsuba_mrt/imageio.py)."""

import errno
import os

import pytest

from mitsuba_mrt import MRTError
from mitsuba_mrt import imageio
from mitsuba_mrt.imageio import OutputSet, check_output_folder


def write_set(folder, names, fail_after=None):
    with OutputSet(folder) as out:
        for k, name in enumerate(names):
            if fail_after is not None and k == fail_after:
                raise KeyboardInterrupt  # as Ctrl-C in the middle of the set
            with open(out.path(name), "w") as f:
                f.write(f"new {name}")


def contents(folder):
    return {p.name: p.read_text() for p in folder.iterdir()}


def test_an_interrupt_in_the_middle_of_the_set_leaves_no_file(tmp_path):
    with pytest.raises(KeyboardInterrupt):
        write_set(tmp_path, ["a.exr", "a.png", "a.json"], fail_after=2)
    assert contents(tmp_path) == {}


@pytest.mark.parametrize("error", [OSError(errno.ENOSPC, "No space left on device"),
                                   KeyboardInterrupt()])
def test_a_failed_rename_puts_the_earlier_files_back(tmp_path, monkeypatch, error):
    (tmp_path / "a.exr").write_text("old a.exr")  # a previous run's
    real = os.replace
    calls = []

    def replace(src, dst):
        calls.append(dst)
        if str(dst).endswith("a.json"):
            raise error
        real(src, dst)

    monkeypatch.setattr(imageio.os, "replace", replace)
    with pytest.raises(MRTError if isinstance(error, OSError) else KeyboardInterrupt):
        write_set(tmp_path, ["a.exr", "a.png", "a.json"])
    assert contents(tmp_path) == {"a.exr": "old a.exr"}  # as before: the set did not appear
    assert any(str(c).endswith("a.png") for c in calls)  # it had been renamed into place


def test_a_whole_set_replaces_the_earlier_files(tmp_path):
    (tmp_path / "a.exr").write_text("old a.exr")
    write_set(tmp_path, ["a.exr", "a.png"])
    assert contents(tmp_path) == {"a.exr": "new a.exr", "a.png": "new a.png"}


def test_output_folder_checked_without_creating_it(tmp_path):
    check_output_folder(tmp_path / "new" / "deeper")
    assert list(tmp_path.iterdir()) == []
    (tmp_path / "file").write_text("")
    with pytest.raises(MRTError, match="is not a folder"):
        check_output_folder(tmp_path / "file" / "out")
    with pytest.raises(MRTError, match="is not a folder"):
        check_output_folder(tmp_path / "file")
