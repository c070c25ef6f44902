"""The example files (case files, meshes, demos) and ``fenics-contact examples DIR``, which copies them out.

A wheel ships the repository's ``cases/``, ``meshes/`` and ``demos/`` as package data under
``fenics_contact/example_files/`` (setup.py maps them there); in a source checkout or an editable install
they are the repository's own folders.  The command copies the three folders into ``DIR`` (created if
missing; a non-empty ``DIR`` is refused, so nothing of the user's is ever overwritten) and says how to run
a copied case.  Case files name their mesh files relative to themselves, so a copied case runs as it is.
"""

import argparse
import sys
from importlib.resources import files
from importlib.resources.abc import Traversable
from pathlib import Path

from mpi4py import MPI

__all__ = ["EXAMPLE_DIRS", "add_examples_parser", "copy_examples", "example_files", "run_examples_command"]

#: the folders of examples, each copied to ``DIR/<name>``
EXAMPLE_DIRS = ("cases", "meshes", "demos")

#: what is not copied: Python's byte-code caches
_SKIPPED_NAMES = ("__pycache__",)
_SKIPPED_SUFFIXES = (".pyc",)


def example_files() -> Traversable:
    """The folder that holds ``cases/``, ``meshes/`` and ``demos/`` (installed package data, else the source tree)."""
    shipped = files("fenics_contact") / "example_files"
    if all((shipped / name).is_dir() for name in EXAMPLE_DIRS):
        return shipped
    tree = Path(__file__).resolve().parents[1]  # a source checkout (an editable install runs from it)
    if all((tree / name).is_dir() for name in EXAMPLE_DIRS):
        return tree
    raise FileNotFoundError(
        f"the example files ({', '.join(EXAMPLE_DIRS)}) are neither installed in {shipped} nor "
        f"in the source tree {tree}: reinstall fenics-contact"
    )


def _copy_tree(source: Traversable, target: Path) -> list[Path]:
    target.mkdir(parents=True, exist_ok=True)
    written = []
    for entry in sorted(source.iterdir(), key=lambda e: e.name):
        if entry.name in _SKIPPED_NAMES or entry.name.endswith(_SKIPPED_SUFFIXES):
            continue
        if entry.is_dir():
            written += _copy_tree(entry, target / entry.name)
        else:
            (target / entry.name).write_bytes(entry.read_bytes())
            written.append(target / entry.name)
    return written


def copy_examples(directory: Path) -> list[Path]:
    """Copy ``cases/``, ``meshes/`` and ``demos/`` into ``directory`` (created; refused unless empty).

    Returns the files written.  Raises FileExistsError when ``directory`` is a non-empty folder or a file.
    """
    directory = Path(directory)
    if directory.exists() and (not directory.is_dir() or any(directory.iterdir())):
        what = "a non-empty folder" if directory.is_dir() else "not a folder"
        raise FileExistsError(f"{directory} is {what}: give a new or empty folder (nothing of yours is overwritten)")
    source = example_files()
    written = []
    for name in EXAMPLE_DIRS:
        written += _copy_tree(source / name, directory / name)
    return written


def add_examples_parser(subparsers: "argparse._SubParsersAction[argparse.ArgumentParser]") -> None:
    """Add the ``examples DIR`` subcommand to the command line's subparsers."""
    parser = subparsers.add_parser(
        "examples",
        help="copy the example case files, meshes and demos into a new folder",
        description="Copy the example case files (cases/), meshes (meshes/) and demos (demos/) into DIR, "
        "created if missing; a non-empty DIR is refused (exit 2). Then e.g. "
        "fenics-contact run --case DIR/cases/bar.toml --out results/bar",
    )
    parser.add_argument("directory", type=Path, metavar="DIR", help="a new or empty folder")


def run_examples_command(args: argparse.Namespace, comm: MPI.Comm = MPI.COMM_WORLD) -> int:
    """``fenics-contact examples DIR``: copy on rank 0; exit 0, or 2 with one line on stderr."""
    problem = None
    written: list[Path] = []
    if comm.rank == 0:
        try:
            written = copy_examples(args.directory)
        except OSError as error:  # FileExistsError: DIR not empty; FileNotFoundError: no example files
            problem = str(error)
    problem = comm.bcast(problem, root=0)
    if problem is not None:
        if comm.rank == 0:
            print(f"error: {problem}", file=sys.stderr, flush=True)
        return 2
    if comm.rank == 0:
        cases = sorted(p.name for p in (args.directory / "cases").glob("*.toml"))
        print(
            f"copied {len(written)} files into {args.directory}: {', '.join(EXAMPLE_DIRS)}\n"
            f"cases: {', '.join(cases)}\n"
            f"run one: fenics-contact run --case {args.directory / 'cases' / 'bar.toml'} --out results/bar",
            flush=True,
        )
    return 0
