import os

import pytest

from mitsuba_mrt.runtime import allocator


def _glibc() -> bool:
    try:
        return os.confstr("CS_GNU_LIBC_VERSION").startswith("glibc")
    except (AttributeError, ValueError, OSError):
        return False


@pytest.mark.skipif(not _glibc(), reason="mallopt is glibc's")
def test_thresholds_are_set_on_glibc(monkeypatch):
    monkeypatch.delenv("MITSUBA_MRT_MALLOC", raising=False)
    for name in allocator._USER_TUNING:
        monkeypatch.delenv(name, raising=False)
    assert allocator.keep_freed_memory() is True


def test_the_thresholds_and_the_top_pad_go_to_mallopt(monkeypatch):
    monkeypatch.delenv("MITSUBA_MRT_MALLOC", raising=False)
    for name in allocator._USER_TUNING:
        monkeypatch.delenv(name, raising=False)
    monkeypatch.setattr(allocator.os, "confstr", lambda name: "glibc 2.36")
    calls = {}

    class Mallopt:  # (a C function: its argument types are set on it)
        def __call__(self, parameter, value):
            calls[parameter] = value
            return 1

    libc = type("Libc", (), {"mallopt": Mallopt()})()
    monkeypatch.setattr(allocator.ctypes, "CDLL", lambda *a: libc)
    assert allocator.keep_freed_memory() is True
    # M_TRIM_THRESHOLD, M_TOP_PAD, M_MMAP_THRESHOLD (malloc.h)
    assert calls == {-1: allocator.TRIM_THRESHOLD, -2: allocator.TOP_PAD,
                     -3: allocator.MMAP_THRESHOLD}


@pytest.mark.parametrize("name,value", [("MITSUBA_MRT_MALLOC", "system"),
                                        ("MALLOC_TRIM_THRESHOLD_", "1000000"),
                                        ("MALLOC_MMAP_THRESHOLD_", "65536")])
def test_user_choices_are_kept(monkeypatch, name, value):
    monkeypatch.setenv(name, value)
    called = []
    monkeypatch.setattr(allocator.ctypes, "CDLL", lambda *a: called.append(a))
    assert allocator.keep_freed_memory() is False
    assert called == []  # the C library was not even opened



@pytest.fixture
def advised():
    """NumPy's huge-page advice, on for the test and restored after it."""
    try:
        from numpy._core import multiarray
    except ImportError:
        from numpy.core import multiarray
    before = multiarray._set_madvise_hugepage(True)
    yield multiarray._get_madvise_hugepage
    multiarray._set_madvise_hugepage(before)


def test_numpy_stops_advising_huge_pages(monkeypatch, advised):
    monkeypatch.delenv("MITSUBA_MRT_MALLOC", raising=False)
    monkeypatch.delenv("NUMPY_MADVISE_HUGEPAGE", raising=False)
    assert allocator.no_huge_pages() is True
    assert advised() is False


@pytest.mark.parametrize("name,value", [("MITSUBA_MRT_MALLOC", "system"),
                                        ("NUMPY_MADVISE_HUGEPAGE", "1")])
def test_numpys_advice_is_left_where_the_user_chose(monkeypatch, advised, name, value):
    monkeypatch.setenv(name, value)
    assert allocator.no_huge_pages() is False
    assert advised() is True
