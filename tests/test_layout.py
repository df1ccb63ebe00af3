"""The package's wings import one way (docs/ARCHITECTURE.md), inline imports included."""

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parent.parent / "mitsuba_mrt"

#: What each wing may import from the package, besides itself and ``errors``.
ALLOWED = {
    "app": {"bench", "imageio", "renderer", "modes", "types", "recon", "runtime"},
    "bench": {"imageio", "renderer", "modes", "types", "recon", "runtime"},
    "renderer": {"modes", "types", "recon", "runtime"},
    "modes": {"types", "recon", "runtime"},
    "types": {"recon"},
    "recon": {"runtime"},
    "runtime": set(),
    "imageio": set(),
    "errors": set(),
}


def _imports(source: str, package: tuple) -> set:
    """The package modules ``source`` imports, dotted below ``mitsuba_mrt``;
    ``package``: the parts of the package it lives in (``("recon",)``)."""
    out = set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                target = list(package[: len(package) - node.level + 1])
                target += node.module.split(".") if node.module else []
            elif node.module and node.module.split(".")[0] == "mitsuba_mrt":
                target = node.module.split(".")[1:]
            else:
                continue
            names = [target] if node.module else [target + [a.name] for a in node.names]
            out.update(".".join(n) for n in names if n)
        elif isinstance(node, ast.Import):
            out.update(a.name.split(".", 1)[1] for a in node.names
                       if a.name.startswith("mitsuba_mrt."))
    return out


def _violations(wing: str, names: set) -> list:
    allowed = ALLOWED[wing] | {wing, "errors"}
    return sorted(n for n in names
                  if not any(n == a or n.startswith(a + ".") for a in allowed))


MODULES = sorted(p for p in PACKAGE.rglob("*.py") if p.parent != PACKAGE
                 or p.stem not in ("__init__", "__main__"))


@pytest.mark.parametrize("path", MODULES, ids=lambda p: str(p.relative_to(PACKAGE)))
def test_each_module_imports_only_its_wing_and_those_below(path):
    parts = path.relative_to(PACKAGE).with_suffix("").parts
    wing = parts[0]
    bad = _violations(wing, _imports(path.read_text(), parts[:-1]))
    assert not bad, f"{path.relative_to(PACKAGE)} ({wing}) imports {bad}"


def test_the_check_sees_a_wrong_import():
    # recon importing types, which imports recon: the cycle the table forbids
    names = _imports("from ..types import MRTParams\nfrom . import compose\n", ("recon",))
    assert names == {"types", "recon.compose"}
    assert _violations("recon", names) == ["types"]
    assert _imports("import mitsuba_mrt.imageio\n", ("bench",)) == {"imageio"}
    assert _imports("from ..imageio import atomic_path\n", ("bench",)) == {"imageio"}
    # bench imports nothing of app: the one arrow that ran back up
    assert _violations("bench", {"imageio", "app.cli", "app.job"}) == ["app.cli", "app.job"]
    assert _violations("imageio", {"errors", "app.job"}) == ["app.job"]
