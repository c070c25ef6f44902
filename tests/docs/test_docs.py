"""The documentation site builds with warnings as errors: pages, the demos executed with inline figures, the API.

The build is the one of ``make docs`` (``docs/conf.py``) at a small demo size (1/h = 16), into a temporary
folder.  A broken internal link, a docstring Sphinx cannot read or a demo that fails is an error.
"""

import importlib
import inspect
import os
import pkgutil
import re
import subprocess
import sys
from pathlib import Path

import pytest
from mpi4py import MPI

import fenics_contact

ROOT = Path(__file__).parents[2]
pytestmark = [pytest.mark.slow, pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="the docs build runs serially")]


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("docs")
    env = dict(os.environ, FENICS_CONTACT_DEMO_N="16", OMP_NUM_THREADS="1")
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "sphinx",
            "-W",
            "--keep-going",
            "-b",
            "html",
            "-d",
            out / "doctrees",
            ROOT / "docs",
            out / "html",
        ],
        env=env,
        capture_output=True,
        text=True,
        timeout=3600,
    )
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-6000:]
    return out / "html"


def test_the_pages_are_there(site):
    for page in (
        "index",
        "getting_started",
        "theory",
        "demos",
        "api",
        "bad_input",
        "user_guide/index",
        "user_guide/case_files",
        "user_guide/cli",
        "user_guide/outputs",
        "user_guide/exit_codes",
    ):
        assert (site / f"{page}.html").is_file(), page
    assert "arXiv:2512.04411" in (site / "index.html").read_text()
    cli = (site / "user_guide" / "cli.html").read_text()
    assert "fenics-contact run" in cli and "fenics-contact examples" in cli and "--max-iterations" in cli


def test_every_demo_is_executed_with_its_figures_inline(site):
    demos = sorted(p.stem for p in (ROOT / "demos").glob("demo_*.py"))
    assert demos
    for demo in demos:
        page = (site / "demos" / f"{demo}.html").read_text()
        assert len(re.findall(r"<img [^>]*src=\"[^\"]*_images/", page)) >= 2, demo  # the PNGs the demo wrote
        assert "Traceback" not in page, demo


def test_every_module_has_an_api_page_with_its_public_names(site):
    """The reference walks the package: a page per module (subpackages too), each documenting the classes and
    functions of its ``__all__`` (the package's top-level API: on the pages of the modules that define it)."""
    modules = ["fenics_contact"] + [
        m.name
        for m in pkgutil.walk_packages(fenics_contact.__path__, "fenics_contact.")
        if not m.name.rsplit(".", 1)[-1].startswith("_")
    ]
    undocumented = {}
    for name in modules:
        page = site / "api" / f"{name}.html"
        assert page.is_file(), name
        html = page.read_text()
        module = importlib.import_module(name)
        public = [
            n
            for n in getattr(module, "__all__", [])
            if inspect.isclass(getattr(module, n)) or inspect.isfunction(getattr(module, n))
        ]
        home = {n: getattr(module, n).__module__ if name == "fenics_contact" else name for n in public}
        # (the package's top-level API is documented on the pages of the modules that define it)
        if missing := [
            n
            for n in public
            if f'id="{home[n]}.{n}"'
            not in (html if home[n] == name else (site / "api" / f"{home[n]}.html").read_text())
        ]:
            undocumented[name] = missing
    assert not undocumented
