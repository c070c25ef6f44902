"""Run the Python code blocks of a documentation page, in order, in one namespace, and print what they print.

    python docs/run_page_examples.py                          # docs/user_guide/problem.md
    python docs/run_page_examples.py docs/user_guide/problem.md

Every ```python block of the page is executed as it stands (a failing block fails the script with the
block's number), so the page's examples are runnable code and the numbers it quotes come from this command.
"""

import re
import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parent
BLOCK = re.compile(r"^```python\n(.*?)^```", re.S | re.M)


def run(page: Path) -> None:
    namespace: dict = {"__name__": "__main__"}
    blocks = BLOCK.findall(page.read_text())
    if not blocks:
        raise SystemExit(f"{page} has no python blocks")
    for number, code in enumerate(blocks, start=1):
        print(f"# block {number}", flush=True)
        exec(compile(code, f"{page.name}, block {number}", "exec"), namespace)  # noqa: S102 (our own pages)


if __name__ == "__main__":
    run(Path(sys.argv[1]) if len(sys.argv) > 1 else DOCS / "user_guide" / "problem.md")
