"""Sphinx configuration of the fenics-contact documentation: MyST Markdown pages.

Made at each build, before Sphinx reads the sources (all ignored by git, docs/.gitignore):

* ``user_guide/generated/``: the ``--help`` of the command line and of each subcommand (from
  ``fenics_contact.cli.build_parser``) and the exit-code table (``fenics_contact.cli.EXIT_CODES``),
  included by the user guide's pages.
"""

import contextlib
import io
import os
import re
from pathlib import Path

import fenics_contact
from fenics_contact.cli import EXIT_CODES, build_parser

DOCS = Path(__file__).resolve().parent

project = "fenics-contact"
author = "the fenics-contact developers"
copyright = "the fenics-contact developers"
version = release = fenics_contact.__version__

extensions = [
    "myst_nb",
    "sphinx.ext.mathjax",
]
exclude_patterns = ["_build", "make_figures.py", "**/.ipynb_checkpoints", "user_guide/generated"]

# MyST: $…$ and $$…$$ math, ::: fences, heading anchors for links to sections
myst_enable_extensions = ["dollarmath", "amsmath", "colon_fence", "deflist"]
myst_heading_anchors = 3

html_theme = "furo"
html_title = f"fenics-contact {release}"


def _write_if_changed(path: Path, text: str) -> None:
    """Write ``text`` unless ``path`` holds it already (an unchanged file keeps Sphinx's cache valid)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    if not path.is_file() or path.read_text() != text:
        path.write_text(text)


def _exit_code_table() -> None:
    rows = "\n".join(f"| {code} | {meaning} |" for code, meaning in EXIT_CODES.items())
    _write_if_changed(DOCS / "user_guide" / "generated" / "exit_codes.md", f"| code | meaning |\n|---|---|\n{rows}\n")


def _cli_help() -> None:
    """The ``--help`` text of ``fenics-contact`` and of each of its subcommands, as Markdown code blocks."""
    os.environ["COLUMNS"] = "100"  # argparse wraps to the terminal's width
    top = build_parser().format_help()
    commands = re.search(r"\{([\w,-]+)\}", build_parser().format_usage()).group(1).split(",")
    blocks = [f"## `fenics-contact`\n\n```text\n{top}```\n"]
    for command in commands:
        text = io.StringIO()
        with contextlib.redirect_stdout(text), contextlib.suppress(SystemExit):
            build_parser().parse_args([command, "--help"])
        blocks.append(f"## `fenics-contact {command}`\n\n```text\n{text.getvalue()}```\n")
    _write_if_changed(DOCS / "user_guide" / "generated" / "cli_help.md", "\n".join(blocks))


_exit_code_table()
_cli_help()
