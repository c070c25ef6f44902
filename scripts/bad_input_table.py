"""Print the bad-input table of the command line (tests/cli/test_bad_input.py) with the messages the package gives.

OMP_NUM_THREADS=1 .venv/bin/python scripts/bad_input_table.py > docs/bad_input.md
"""

import contextlib
import io
import os
import sys
import tempfile
from pathlib import Path

import fenics_contact  # noqa: F401  (before dolfinx)

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT / "tests" / "cli"), str(ROOT / "tests")]

from test_bad_input import CASES  # noqa: E402

from fenics_contact.cli import EXIT_CODES, main  # noqa: E402


def run(case) -> tuple[int, str]:
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        cwd = os.getcwd()
        os.chdir(tmp)
        try:
            args = case.prepare(tmp)
            if "--out" not in args:
                args += ["--out", str(tmp / "out")]
            err = io.StringIO()
            with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err):
                code = main(["run", "--no-plots", *args])
        finally:
            os.chdir(cwd)
        # paths in messages relative to the checkout, so the table does not depend on where it was made
        return code, err.getvalue().strip().replace(str(tmp), "<tmp>").replace(str(ROOT) + "/", "")


def main_table() -> None:
    print("# The command line on bad input\n")
    print(
        "Made by `OMP_NUM_THREADS=1 .venv/bin/python scripts/bad_input_table.py > docs/bad_input.md` from the cases of"
    )
    print(
        "`tests/cli/test_bad_input.py` (each case there asserts the exit code, the one line on stderr, and that nothing"
        " is"
    )
    print("written). Exit codes: " + "; ".join(f"{c} {m}" for c, m in EXIT_CODES.items()) + ".\n")
    print("| case | exit | message (stderr, one line) |")
    print("|---|---|---|")
    for case in CASES:
        code, message = run(case)
        message = message.replace("|", "\\|")
        print(f"| {case.name} | {code} | {message} |")


if __name__ == "__main__":
    main_table()
