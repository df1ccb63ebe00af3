#!/usr/bin/env python3
"""Set up and run mitsuba-mrt on a fresh machine with nothing but Python.

    python3 run.py render   # MRT + reference of scenes_xml/paper_fig1.xml (path, 64 spp) into out/
    python3 run.py test     # the test suite
    python3 run.py stress   # the stress suite, thorough (about 15 minutes), and its table
    python3 run.py bench ARGS...  # python -m mitsuba_mrt bench ARGS...

Each command creates .venv (if missing), installs the package into it,
and, when Dr.Jit finds no libLLVM >= 17, tries to install Debian's
libllvm19 (as root, with apt-get); without it the slow scalar variant is used.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import sys
import venv
from pathlib import Path

ROOT = Path(__file__).resolve().parent
VENV = ROOT / ".venv"
PYTHON = VENV / ("Scripts/python.exe" if os.name == "nt" else "bin/python")
STAMP = VENV / ".installed"


def say(message: str) -> None:
    print(f"[run.py] {message}", flush=True)


def setup() -> None:
    if not PYTHON.exists():
        say(f"creating {VENV}")
        venv.EnvBuilder(with_pip=True).create(VENV)
    digest = hashlib.sha256((ROOT / "pyproject.toml").read_bytes()).hexdigest()
    if not STAMP.exists() or STAMP.read_text() != digest:
        say("installing mitsuba-mrt and its dependencies")
        subprocess.run([str(PYTHON), "-m", "pip", "install", "-q", "--upgrade", "pip"], check=True)
        # with the batch, denoise and bench extras, so that the test suite covers
        # the batch command, denoise="oidn" and the bench's FLIP
        subprocess.run([str(PYTHON), "-m", "pip", "install", "-q", "-e",
                        f"{ROOT}[test,batch,denoise,bench]"], check=True)
        STAMP.write_text(digest)
    ensure_llvm()


def llvm_major() -> int:
    code = "import drjit; v = drjit.detail.llvm_version(); print(v[0] if v else 0)"
    out = subprocess.run([str(PYTHON), "-c", code], capture_output=True, text=True)
    try:
        return int(out.stdout.strip() or 0)
    except ValueError:
        return 0


def ensure_llvm() -> None:
    if llvm_major() >= 17:
        return
    apt = shutil.which("apt-get")
    is_root = hasattr(os, "geteuid") and os.geteuid() == 0
    if apt and is_root:
        say("libLLVM >= 17 not found; installing Debian's libllvm19")
        env = dict(os.environ, DEBIAN_FRONTEND="noninteractive")
        ok = subprocess.run([apt, "update", "-qq"], env=env).returncode == 0 and \
            subprocess.run([apt, "install", "-y", "-qq", "libllvm19"], env=env,
                           stdout=subprocess.DEVNULL).returncode == 0
        if ok and llvm_major() >= 17:
            return
    say("no libLLVM >= 17: using the slow scalar variant "
        "(install libllvm19 or another libLLVM 17+ for the LLVM variant)")


def main(argv: list[str]) -> int:
    if not argv or argv[0] not in ("render", "test", "stress", "bench"):
        print(__doc__.strip())
        return 2
    setup()
    command, rest = argv[0], argv[1:]
    if command == "render":
        # path tracing at 64 spp: where tracing costs enough for the MRT to pay off
        args = ["-m", "mitsuba_mrt", "render", str(ROOT / "scenes_xml" / "paper_fig1.xml"),
                "-o", str(ROOT / "out"), "-D", "integrator=path", "-D", "spp=64",
                "-D", "jitter=true"] + rest
    elif command == "bench":
        args = ["-m", "mitsuba_mrt", "bench"] + rest
    elif command == "stress":
        # 1000 cases per property and mode; tests/stress/conftest.py prints the
        # table of cases and failures at the end
        env = dict(os.environ, MITSUBA_MRT_STRESS="thorough")
        args = ["-m", "pytest", "-q", "-p", "no:cacheprovider", str(ROOT / "tests" / "stress")]
        return subprocess.run([str(PYTHON)] + args + rest, cwd=ROOT, env=env).returncode
    else:
        args = ["-m", "pytest", "-q"] + rest
    return subprocess.run([str(PYTHON)] + args, cwd=ROOT).returncode


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
