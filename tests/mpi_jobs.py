"""Helpers for the tests that launch their own MPI job (``mpiexec -n N python script ...``)."""

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path


def mpiexec() -> str | None:
    """The venv's ``mpiexec`` (the mpich wheel's), else the one on PATH, else None."""
    local = Path(sys.executable).with_name("mpiexec")
    return str(local) if local.exists() else shutil.which("mpiexec")


def run_result(script: Path, prefix: list[str], *args: str, timeout: float) -> dict:
    """Run ``[*prefix, python, script, *args]`` (one thread per process) and return the JSON of its ``RESULT`` line."""
    env = dict(os.environ, OMP_NUM_THREADS="1")
    proc = subprocess.run([*prefix, sys.executable, str(script), *args], capture_output=True, text=True,
                          env=env, timeout=timeout)
    assert proc.returncode == 0, proc.stderr[-3000:]
    line = next(l for l in proc.stdout.splitlines() if l.startswith("RESULT "))  # noqa: E741
    return json.loads(line[len("RESULT "):])
