import pytest

from mitsuba_mrt import MRTError
from mitsuba_mrt.renderer import variants
from mitsuba_mrt.runtime import jit


def test_auto_falls_back_to_scalar_with_one_line_warning(monkeypatch):
    monkeypatch.setattr(jit, "llvm_version", lambda: (15, 0, 7))
    said = []
    assert variants.choose_variant("auto", warn=said.append) == "scalar_rgb"
    assert len(said) == 1 and "\n" not in said[0]
    assert "libLLVM 15.0.7" in said[0] and "libllvm19" in said[0]


def test_auto_picks_llvm_when_17_or_newer(monkeypatch):
    monkeypatch.setattr(jit, "llvm_version", lambda: (17, 0, 0))
    assert variants.choose_variant("auto") == "llvm_ad_rgb"


def test_explicit_llvm_without_llvm_is_refused(monkeypatch):
    monkeypatch.setattr(jit, "llvm_version", lambda: None)
    with pytest.raises(MRTError, match="libLLVM >= 17"):
        variants.choose_variant("llvm_ad_rgb")


def test_unknown_variant():
    with pytest.raises(MRTError, match="unknown variant 'llvm_rgb'"):
        variants.choose_variant("llvm_rgb")
