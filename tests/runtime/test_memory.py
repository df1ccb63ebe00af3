"""What earlier processes measured, kept on disk (mitsuba_mrt.runtime.memory)."""

import json

import pytest

from mitsuba_mrt.runtime import memory


@pytest.fixture
def file(tmp_path, monkeypatch):
    path = tmp_path / "cache" / "memory.json"
    monkeypatch.setenv("MITSUBA_MRT_MEMORY", str(path))
    return path


def test_what_is_remembered_is_recalled_and_the_file_keeps_the_latest_scenes(file, monkeypatch):
    assert memory.enabled() and memory.recall("a") is None  # (no file yet)
    memory.remember("a", {"x": 1})
    memory.remember("b", {"x": 2})
    assert memory.recall("a") == {"x": 1} and memory.recall("b") == {"x": 2}
    monkeypatch.setattr(memory, "KEPT_SCENES", 2)
    memory.remember("a", {"x": 3})  # (now the most recent)
    memory.remember("c", {"x": 4})
    assert memory.recall("b") is None and memory.recall("a") == {"x": 3}
    assert sorted(json.loads(file.read_text())["scenes"]) == ["a", "c"]
    assert [p.name for p in file.parent.iterdir()] == [file.name]  # (no temporary left)


def test_a_file_of_another_format_or_garbage_is_as_none(file):
    file.parent.mkdir(parents=True)
    for text in ("not json", json.dumps({"version": 0, "scenes": {"a": {}}}),
                 json.dumps({"version": memory.VERSION, "scenes": {"a": 1}}), "[]"):
        file.write_text(text)
        assert memory.recall("a") is None
    memory.remember("a", {"x": 1})  # (replaced whole)
    assert memory.recall("a") == {"x": 1}


def test_off_reads_and_writes_nothing_and_an_unwritable_place_is_no_error(tmp_path, monkeypatch):
    monkeypatch.setenv("MITSUBA_MRT_MEMORY", "off")
    assert not memory.enabled() and memory.path() is None
    memory.remember("a", {"x": 1})
    assert memory.recall("a") is None
    blocker = tmp_path / "a_file"
    blocker.write_text("")
    monkeypatch.setenv("MITSUBA_MRT_MEMORY", str(blocker / "memory.json"))  # (under a file)
    memory.remember("a", {"x": 1})
    assert memory.recall("a") is None


@pytest.mark.parametrize("setting", ["0", "false", "No", " OFF "])
def test_the_usual_words_for_off_are_off(setting, tmp_path, monkeypatch):
    # (MITSUBA_MRT_MEMORY=0 wrote a memory file named 0 in the working folder)
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("MITSUBA_MRT_MEMORY", setting)
    memory.remember("a", {"x": 1})
    assert not memory.enabled() and list(tmp_path.iterdir()) == []
