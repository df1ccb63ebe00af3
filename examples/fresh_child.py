"""One measurement in a fresh Python process, as a user's first render runs:
what the examples that time fresh processes share."""

import json
import os
import subprocess
import sys
import tempfile


def fresh_child(program: str, *args: str, what: str, memory: str | None = "off",
                cold: bool = False, cwd=None) -> dict:
    """The last line of ``python -c program args...``'s output, read as JSON.

    The child runs as a user's Python does: the package's modules compiled
    once and their bytecode kept (a shell with ``PYTHONDONTWRITEBYTECODE``
    would compile them in every process).  ``memory``: its
    ``MITSUBA_MRT_MEMORY`` (None: this process's); ``cold``: an empty
    ``HOME``, so that Dr.Jit's kernel cache starts empty.  Where the child
    fails, this process exits with one line naming ``what`` and the child's
    last line of error (or printed no JSON line).
    """
    env = dict(os.environ)
    if memory is not None:
        env["MITSUBA_MRT_MEMORY"] = memory
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    with tempfile.TemporaryDirectory() as home:
        if cold:  # (Dr.Jit keeps its kernel cache under HOME)
            env["HOME"] = home
        out = subprocess.run([sys.executable, "-c", program, *args], env=env, cwd=cwd,
                             capture_output=True, text=True)
    if out.returncode != 0:
        lines = out.stderr.strip().splitlines() or [f"exit status {out.returncode}"]
        print(f"error: {what} failed: {lines[-1]}", file=sys.stderr)
        sys.exit(2)
    # its figures: the last JSON object on a line (Mitsuba's coloured log may
    # share the line, its colour's reset before the object)
    for line in reversed(out.stdout.strip().splitlines()):
        if "{" in line:
            try:
                return json.loads(line[line.index("{"):])
            except ValueError:
                continue
    print(f"error: {what} printed no figures", file=sys.stderr)
    sys.exit(2)
