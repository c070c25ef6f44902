"""Sphinx configuration of the fenics-contact documentation: MyST Markdown pages, the demos as notebooks.

Made at each build, before Sphinx reads the sources (all ignored by git, docs/.gitignore):

* ``demos/*.ipynb``: the jupytext percent scripts of the repository's ``demos/`` as notebooks, executed by
  MyST-NB with their figures inline, at the size ``FENICS_CONTACT_DEMO_N`` (``make docs DEMO_N=…``);
* ``api/``: one page per module of the package, found recursively (autosummary), so the reference follows
  the package layout;
* ``user_guide/generated/``: the ``--help`` of the command line and of each subcommand (from
  ``fenics_contact.cli.build_parser``), the exit-code table (``fenics_contact.cli.EXIT_CODES``) and the
  key reference of the case files (``make_case_reference.py``, from the code that reads them), included
  by the user guide's pages.

The package's docstrings are plain text (Unicode math, double-backquoted literals, Google-style
``Args:``/``Returns:`` sections); ``plain_text_docstring`` reads them as such for autodoc.
"""

import contextlib
import io
import os
import re
import sys
from pathlib import Path

import jupytext
from sphinx.ext import napoleon
from sphinx.ext.napoleon.docstring import GoogleDocstring

import fenics_contact
from fenics_contact.cli import EXIT_CODES, build_parser

DOCS = Path(__file__).resolve().parent
ROOT = DOCS.parent
sys.path.insert(0, str(DOCS))
import make_case_reference  # noqa: E402  (a script beside this file)

# the demos run at 1/h = FENICS_CONTACT_DEMO_N, and write their PNGs with a non-interactive backend (the
# pages show the PNG files, not matplotlib's own inline figures)
DEMO_N = os.environ.setdefault("FENICS_CONTACT_DEMO_N", "32")
os.environ["MPLBACKEND"] = "Agg"
os.environ.setdefault("OMP_NUM_THREADS", "1")

project = "fenics-contact"
author = "the fenics-contact developers"
copyright = "the fenics-contact developers"
version = release = fenics_contact.__version__

extensions = [
    "myst_nb",
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.mathjax",
]
templates_path = ["_templates"]
exclude_patterns = ["_build", "*.py", "**/.ipynb_checkpoints", "user_guide/generated"]

# MyST: $…$ and $$…$$ math, ::: fences, heading anchors for links to sections
myst_enable_extensions = ["dollarmath", "amsmath", "colon_fence", "deflist"]
myst_heading_anchors = 3

# MyST-NB: execute each demo notebook (cached per DEMO_N; a failing cell fails the build)
nb_execution_mode = "cache"
nb_execution_cache_path = str(DOCS / "_build" / ".jupyter_cache" / f"n{DEMO_N}")
nb_execution_timeout = 3600
nb_execution_raise_on_error = True
nb_execution_in_temp = True
nb_output_stderr = "remove"
nb_merge_streams = True

# API reference
autosummary_generate = True
autosummary_ignore_module_all = True  # the package tree by its files; each page's members follow its __all__
autodoc_member_order = "bysource"
autodoc_typehints = "signature"
# Google-style sections (Args:, Returns:) of functions and classes, read by napoleon from
# plain_text_docstring below; an attribute's one-line doc is prose (napoleon would read "(n, 3) …: …" as a type)
NAPOLEON = napoleon.Config(napoleon_google_docstring=True, napoleon_numpy_docstring=False, napoleon_use_rtype=False)

# literal blocks without a language (the docstrings' displayed formulas and tables) are not Python
highlight_language = "none"

html_theme = "furo"
html_title = f"fenics-contact {release}"


def _write_if_changed(path: Path, text: str) -> None:
    """Write ``text`` unless ``path`` holds it already (an unchanged file keeps Sphinx's cache valid)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    if not path.is_file() or path.read_text() != text:
        path.write_text(text)


def _demo_notebooks() -> None:
    """``demos/<name>.ipynb`` for every ``<root>/demos/demo_*.py``; notebooks of removed demos are removed."""
    scripts = sorted((ROOT / "demos").glob("demo_*.py"))
    for script in scripts:
        _write_if_changed(DOCS / "demos" / f"{script.stem}.ipynb", jupytext.writes(jupytext.read(script), fmt="ipynb"))
    for notebook in (DOCS / "demos").glob("*.ipynb"):
        if notebook.stem not in {s.stem for s in scripts}:
            notebook.unlink()


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


_LITERAL = re.compile(r"(``.+?``)")
_BULLET = re.compile(r"^(\s*)([*-]|\d+\.)\s+")


def _leading(line: str) -> int:
    return len(line) - len(line.lstrip())


def _text_column(line: str) -> int:
    """The column where a line's text starts (after the marker, for a list item)."""
    bullet = _BULLET.match(line)
    return bullet.end() if bullet else _leading(line)


def plain_text_docstring(app, what, name, obj, options, lines: list[str]) -> None:
    """Read the package's docstrings as what they are: plain text with double-backquoted literals and a few roles.

    Two plain-text conventions of the package mean something else in reStructuredText, and are made literal:

    * a block indented under the paragraph before it, after a blank line, is displayed as it is (formulas,
      tables, TOML): it becomes a literal block;
    * ``|`` is a norm or an absolute value (``|x|``, ``‖Ax‖``), never a substitution, and a word's trailing
      ``_`` is text, not a link target: both are escaped outside literals.

    Then napoleon reads the Google-style sections of functions and classes.
    """
    out: list[str] = []
    k = 0
    paragraph_indent = 0  # the text column of the paragraph before the current line
    while k < len(lines):
        line = lines[k]
        after_blank = k > 0 and not lines[k - 1].strip()
        if (
            line.strip()
            and after_blank
            and k > 1
            and _leading(line) > paragraph_indent
            and not out[-2].rstrip().endswith("::")
            and not out[-2].lstrip().startswith(".. ")
        ):
            block = []
            while k < len(lines) and (not lines[k].strip() or _leading(lines[k]) > paragraph_indent):
                block.append(lines[k])
                k += 1
            while block and not block[-1].strip():
                block.pop()
                k -= 1
            out += [" " * paragraph_indent + "::", ""] + block
            continue
        if line.strip() and (k == 0 or not lines[k - 1].strip()):
            paragraph_indent = _text_column(line)
        parts = _LITERAL.split(line)
        for i in range(0, len(parts), 2):
            parts[i] = re.sub(r"(\w)_(?=\W|$)", r"\1\\_", parts[i].replace("|", "\\|"))
        out.append("".join(parts))
        k += 1
    if what not in ("attribute", "data", "property"):
        out = GoogleDocstring(out, NAPOLEON, app, what, name, obj, options).lines()
    lines[:] = out


def skip_top_level_reexports(app, what, name, obj, skip, options):
    """The package's top-level names (``fenics_contact.solve``, ``ContactProblem``…) are documented where they
    are defined; the package page only lists them (its docstring), so nothing is described twice."""
    on_package_page = app.env.docname == "api/fenics_contact"
    if on_package_page and what == "module" and name in fenics_contact._API:
        return True
    return skip


def setup(app) -> None:
    app.connect("autodoc-process-docstring", plain_text_docstring)
    app.connect("autodoc-skip-member", skip_top_level_reexports)


def _case_keys() -> None:
    _write_if_changed(DOCS / "user_guide" / "generated" / "case_keys.md", make_case_reference.markdown())


_demo_notebooks()
_exit_code_table()
_cli_help()
_case_keys()
