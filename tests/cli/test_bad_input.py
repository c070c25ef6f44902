"""The command line on bad input: a table of cases, each with the exit code and the one-line message it gets.

Every case is refused — most before the mesh is built, the numerical failures (exit 4) by the solve's
own checks — and prints exactly one line on stderr, no traceback, and writes nothing. ``scripts/bad_input_table.py``
prints this
table with the messages as the package gives them (docs/bad_input.md).
"""

import json
from pathlib import Path
from typing import Callable, NamedTuple

import numpy as np
import pytest
from mpi4py import MPI
from outcome import outcome_lines
from user_meshes import GOOD, build_columns
from user_meshes import solid_or_quads as _solid_or_quads

from fenics_contact.cli import main
from fenics_contact.fem.mixed import epsilon_hint

pytestmark = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="the CLI tests run serially")

STORED_MESH = Path(__file__).parents[2] / "meshes" / "unit_square_n16_H4.msh"
SMALL = ["--h", "16", "--H", "4"]


class Case(NamedTuple):
    """One bad input: ``prepare(tmp)`` writes the files it needs and returns the arguments after ``run``."""

    name: str
    prepare: Callable[[Path], list[str]]
    code: int
    message: str  #: a part of the one-line message


def _args(*args: str) -> Callable[[Path], list[str]]:
    return lambda tmp: [*SMALL, *args]


def _e_map(values, name="E.npy", *, raw: bytes | None = None, text: str | None = None):
    def prepare(tmp: Path) -> list[str]:
        path = tmp / name
        if raw is not None:
            path.write_bytes(raw)
        elif text is not None:
            path.write_text(text)
        else:
            np.save(path, values)
        return [*SMALL, "--E-map", str(path)]

    return prepare


def _nan_pixel_between_cell_centres() -> np.ndarray:
    """64 x 64 pixels, one NaN where no cell centre of the h = 1/16 mesh samples it (refused all the same)."""
    values = np.ones((64, 64))
    values[0, 0] = np.nan  # the corner pixel [0, 1/64)²: the nearest cell centre is at (1/48, 1/48)
    return values


def _mesh_file(**kwargs):
    def prepare(tmp: Path) -> list[str]:
        return ["--mesh", str(build_columns(tmp / "user.msh", **kwargs)), "--H", "4"]

    return prepare


def _mesh_text(text: str):
    def prepare(tmp: Path) -> list[str]:
        (tmp / "user.msh").write_text(text)
        return ["--mesh", str(tmp / "user.msh")]

    return prepare


def _tetrahedra(tmp: Path) -> list[str]:
    return ["--mesh", str(_solid_or_quads(tmp / "solid.msh", "tetrahedra"))]


def _out(make: Callable[[Path], str]):
    return lambda tmp: [*SMALL, "--out", make(tmp)]


def _file(tmp: Path) -> Path:
    path = tmp / "a_file"
    path.write_text("not a directory\n")
    return path


def _foreign_directory(tmp: Path) -> str:
    path = tmp / "mine"
    path.mkdir()
    (path / "thesis.tex").write_text("\\documentclass{article}\n")
    return str(path)


def _cache(make: Callable[[Path], str], method: str = "primal-ms"):
    return lambda tmp: [*SMALL, "--method", method, "--layers", "1", "--cache-dir", make(tmp)]


# case files
CASES_DIR = Path(__file__).parents[2] / "cases"
#: a small bar on the unit square (clamped on the left), to be spoiled by each case below
SQUARE = """[mesh]
builtin = "unit-square"
h = 8
H = 2
clamped = ["left"]
[material]
E = 1.0
nu = 0.0
[load]
body-force = [1.0, 0.0]
"""
#: the composite of cases/ (materials by group, a traction group on the top)
COMPOSITE = f"""[mesh]
file = "{CASES_DIR / "composite.msh"}"
[material]
E = {{matrix = 1.0, fibres = 1e3}}
nu = 0.3
[boundary]
tractions = {{Gamma_N_top = [0.0, -0.01]}}
"""
CUBE = """[mesh]
builtin = "unit-cube"
h = 4
H = 2
[material]
E = 1.0
nu = 0.3
"""
PLANE = """[obstacle]
shape = "plane"
point = [1.0, 0.0]
normal = [-1.0, 0.0]
"""


def _case(text: str, *args: str, files: dict | None = None):
    """A case file with ``text`` (and ``files`` beside it: name -> text, or an array for .npy)."""

    def prepare(tmp: Path) -> list[str]:
        for name, content in (files or {}).items():
            if isinstance(content, np.ndarray):
                np.save(tmp / name, content)
            else:
                (tmp / name).write_text(content)
        (tmp / "case.toml").write_text(text)
        return ["--case", str(tmp / "case.toml"), *args]

    return prepare


def _case_mesh(text: str, **kwargs):
    """A case on a mesh file of three columns (test_validation.build_columns) tagged as asked."""

    def prepare(tmp: Path) -> list[str]:
        mesh = build_columns(tmp / "user.msh", **kwargs)
        (tmp / "case.toml").write_text(f'[mesh]\nfile = "{mesh}"\n' + text)
        return ["--case", str(tmp / "case.toml")]

    return prepare


_MATERIAL = "[material]\nE = 1.0\nnu = 0.3\n[load]\nbody-force = [1.0, 0.0]\n"


CASES = [
    # options
    Case("ν = 0.5", _args("--nu", "0.5"), 2, "Poisson ratio"),
    Case("ν = nan", _args("--nu", "nan"), 2, "--nu must be a finite number"),
    Case("negative E", _args("--E-low", "-1"), 2, "--E-low (a Young's modulus) must be a finite number > 0"),
    Case("E = inf", _args("--E-high", "inf"), 2, "--E-high (a Young's modulus) must be a finite number > 0"),
    Case("E = nan", _args("--E-high", "nan"), 2, "--E-high (a Young's modulus) must be a finite number > 0"),
    Case("H does not divide h", _args("--H", "5"), 2, "--h 16 is not a multiple of --H 5"),
    Case("h = 1", lambda tmp: ["--h", "1", "--H", "2"], 2, "--h must be an integer >= 2"),
    Case("negative α", _args("--alpha", "-3"), 2, "transmission coefficient --alpha '-3'"),
    Case("unreadable α", _args("--alpha", "h^x"), 2, "transmission coefficient --alpha 'h^x'"),
    Case(
        "δ = inf (contact switched off)", _args("--delta", "inf"), 2, "--delta (the primal penalty δ) must be a finite"
    ),
    Case("δ = 0", _args("--delta", "0"), 2, "--delta (the primal penalty δ) must be a finite number > 0"),
    Case("ε = inf", _args("--method", "mixed", "--epsilon", "inf"), 2, "--epsilon (the mixed penalty ε)"),
    Case("β = 0", _args("--method", "mixed", "--beta", "0"), 2, "transmission coefficient β must be > 0"),
    Case("tolerance 0", _args("--tol", "0"), 2, "relative tolerance must lie in (0, 1)"),
    Case("tolerance nan", _args("--tol", "nan"), 2, "relative tolerance must lie in (0, 1)"),
    Case("no iterations", _args("--max-iterations", "0"), 2, "max_iterations must be an integer >= 1"),
    Case("negative layers", _args("--method", "primal-ms", "--layers", "-1"), 2, "--layers must be an integer >= 0"),
    Case("no modes", _args("--method", "primal-ms", "--nbasis", "0"), 2, "--nbasis must be an integer >= 1"),
    Case("negative min-gap", _args("--method", "mixed-ms", "--min-gap", "-1"), 2, "--min-gap must be"),
    Case(
        "H = h for a multiscale method",
        lambda tmp: ["--h", "8", "--H", "8", "--method", "mixed-ms"],
        2,
        "must span at least 2 fine cells per side",
    ),
    Case(
        "δ for a mixed method",
        _args("--method", "mixed", "--delta", "1e-4"),
        2,
        "--delta does not apply to --method mixed",
    ),
    Case("layers for Algorithm 1", _args("--layers", "3"), 2, "--layers does not apply to --method primal"),
    Case(
        "--E-map with --E-high",
        lambda tmp: [*_e_map(np.ones((4, 4)))(tmp), "--E-high", "5"],
        2,
        "give one or the other",
    ),
    Case(
        "--h with --mesh", lambda tmp: ["--mesh", str(STORED_MESH), "--h", "16"], 2, "--h sets the size of the built-in"
    ),
    Case("mesh too coarse for the load", lambda tmp: ["--h", "4", "--H", "2"], 2, "zero on every cell"),
    # the E map
    Case("E map missing", lambda tmp: [*SMALL, "--E-map", str(tmp / "none.npy")], 2, "does not exist"),
    Case(
        "E map with a NaN pixel no cell centre samples",
        _e_map(_nan_pixel_between_cell_centres()),
        2,
        "pixels the domain covers are not a finite Young's modulus > 0 (first: row 0, column 0, value nan)",
    ),
    Case(
        "E map with a negative pixel",
        _e_map(np.where(np.eye(32) > 0, -1.0, 1.0)),
        2,
        "pixels the domain covers are not a finite Young's modulus > 0",
    ),
    Case("empty .npy file", _e_map(None, raw=b""), 2, "cannot read a pixel array"),
    Case(".npy with no pixels", _e_map(np.zeros((0, 3))), 2, "must hold a non-empty 2D array"),
    Case("1D .npy", _e_map(np.ones(5)), 2, "must hold a non-empty 2D array, got shape (5,)"),
    Case("ragged .csv", _e_map(None, "E.csv", text="1,2\n3\n"), 2, "cannot read a pixel array"),
    Case(".npy of strings", _e_map(np.array([["a", "b"]])), 2, "does not hold numbers"),
    # the mesh file
    Case("mesh missing", lambda tmp: ["--mesh", str(tmp / "none.msh")], 2, "does not exist"),
    Case("mesh not a gmsh file", _mesh_text("hello\nworld\n"), 2, "cannot read"),
    Case("empty mesh file", _mesh_text(""), 2, "cannot read"),
    Case("second-order tetrahedral mesh", _tetrahedra, 2, "4-node tetrahedra only"),
    Case(
        "Gamma_C as a surface group",
        _mesh_file(gamma_c=(), surface_groups={"Omega1": ("A", "B"), "Omega2": ("C",), "Gamma_C": ("C",)}),
        2,
        "'Gamma_C' is a surface group",
    ),
    Case("mesh off the plane z = 0", _mesh_file(z=1.0), 2, "z ≠ 0"),
    Case(
        "gamma on the wrong curve",
        _mesh_file(gamma=("v0",), gamma_d=("b0", "b1", "b2", "t0", "t1", "t2")),
        2,
        "segments of 'gamma' lie on the outer boundary",
    ),
    Case("non-conforming gamma", _mesh_file(interface="hanging"), 2, "the mesh is not conforming"),
    Case(
        "Gamma_C on Omega1",
        _mesh_file(gamma_c=("v0",), gamma_d=("b0", "b1", "b2", "t0", "t1", "t2", "v3")),
        2,
        "segments of 'Gamma_C' are not on the boundary of Omega2",
    ),
    Case(
        "Gamma_D and Gamma_C overlap",
        _mesh_file(gamma_d=(*GOOD["gamma_d"], "v3")),
        2,
        "'Gamma_C' and 'Gamma_D' share 8 segments",
    ),
    Case(
        "coarse grid not resolved (multiscale)",
        lambda tmp: ["--mesh", str(STORED_MESH), "--H", "3", "--method", "primal-ms"],
        2,
        "cross the edges of the coarse grid",
    ),
    # the output directory
    Case("--out an existing file", _out(lambda tmp: str(_file(tmp))), 2, "exists and is a file"),
    Case("--out below a file", _out(lambda tmp: str(_file(tmp) / "run")), 2, "which is a file, not a directory"),
    Case("--out empty", _out(lambda tmp: ""), 2, "--out must name a directory"),
    Case("--out the current directory", _out(lambda tmp: "."), 2, "is the current directory"),
    Case("--out name too long", _out(lambda tmp: str(tmp / ("x" * 300))), 2, "longer than the 255 bytes"),
    Case("--out not writable", _out(lambda tmp: "/proc/fenics-contact-out"), 2, "--out /proc/fenics-contact-out"),
    Case("--out someone else's directory", _out(_foreign_directory), 2, "not the output of a fenics-contact run"),
    # the offline cache directory
    Case("--cache-dir an existing file", _cache(lambda tmp: str(_file(tmp))), 2, "exists and is a file"),
    Case("--cache-dir below a file", _cache(lambda tmp: str(_file(tmp) / "cache")), 2, "which is a file"),
    Case(
        "--cache-dir not writable (before the offline phase)",
        _cache(lambda tmp: "/proc/fenics-contact-cache"),
        2,
        "offline cache directory /proc/fenics-contact-cache is not writable",
    ),
    Case(
        "--cache-dir for Algorithm 1",
        lambda tmp: [*SMALL, "--cache-dir", str(tmp)],
        2,
        "--cache-dir does not apply to --method primal",
    ),
    # case files (--case): schema, groups, boundary conditions, obstacle, run tables
    Case("case file missing", lambda tmp: ["--case", str(tmp / "none.toml")], 2, "none.toml does not exist"),
    Case(
        "case with --coarse-groups",
        _case(SQUARE, "--method", "primal-ms", "--coarse-groups"),
        2,
        "--coarse-groups does not apply to --case",
    ),
    Case("case file not TOML", _case("[mesh\nh = 8\n"), 2, "not a valid TOML file"),
    Case("case: unknown table", _case(SQUARE + "[solver]\ntol = 1e-6\n"), 2, "unknown key or table 'solver'"),
    Case("case: unknown key", _case(SQUARE.replace("h = 8", "hh = 8")), 2, "unknown key 'mesh.hh'"),
    Case(
        "case: wrong type",
        _case(SQUARE.replace("h = 8", 'h = "eight"')),
        2,
        "mesh.h must be an integer >= 2, got 'eight'",
    ),
    Case(
        "case: h not a multiple of H",
        _case(SQUARE.replace("H = 2", "H = 3")),
        2,
        "mesh.h = 8 is not a multiple of mesh.H = 3",
    ),
    Case("case: ν = 0.5", _case(SQUARE.replace("nu = 0.0", "nu = 0.5")), 2, "material.nu must lie in (-1, 0.5)"),
    Case("case: negative E", _case(SQUARE.replace("E = 1.0", "E = -1.0")), 2, "material.E must be > 0, got -1.0"),
    Case(
        "case: E pixel map with a negative pixel under the domain",
        _case(SQUARE.replace("E = 1.0", 'E = {pixels = "E.npy"}'), files={"E.npy": np.array([[1.0, -1.0]])}),
        2,
        "material.E: 1 pixels of E.npy under the domain lie outside (0, inf)",
    ),
    Case(
        "case: python field without that function",
        _case(
            SQUARE.replace("body-force = [1.0, 0.0]", 'body-force = {python = "f.py:force"}'),
            files={"f.py": "def other(x):\n    return x\n"},
        ),
        2,
        "has no callable 'force'",
    ),
    Case(
        "case: python field calling sys.exit(0)",
        _case(
            SQUARE.replace("body-force = [1.0, 0.0]", 'body-force = {python = "f.py:force"}'),
            files={"f.py": "import sys\n\ndef force(x):\n    sys.exit(0)\n"},
        ),
        2,
        "called sys.exit(0) at the cell midpoints",
    ),
    Case(
        "case: python module calling sys.exit on import",
        _case(
            SQUARE.replace("body-force = [1.0, 0.0]", 'body-force = {python = "f.py:force"}'),
            files={"f.py": "import sys\n\nsys.exit(0)\n"},
        ),
        2,
        "f.py called sys.exit(0)",
    ),
    Case(
        "case: an explicit zero load (nothing loads the body)",
        _case(SQUARE.replace("body-force = [1.0, 0.0]", "body-force = [0.0, 0.0]")),
        2,
        "nothing loads the body of 'case': its body force is zero everywhere in it",
    ),
    Case(
        "case: --model where the case gives E, nu and the body force",
        _case(SQUARE, "--model", "2"),
        2,
        "--model 2 would change nothing: case case.toml gives material.E, material.nu and load.body-force",
    ),
    Case(
        "case: --E-high where the case gives E",
        _case(SQUARE.replace("[material]\n", "[material]\nmodel = 1\n"), "--E-high", "5"),
        2,
        "--E-high sets a built-in model's E, but case case.toml gives material.E",
    ),
    Case(
        "case: Hertz block refined beyond the memory",
        lambda tmp: ["--case", str(CASES_DIR / "hertz.toml"), "--set", "mesh.refinement=1000"],
        2,
        "would need about",
    ),
    Case(
        "case: a material group on a built-in mesh",
        _case(SQUARE.replace("E = 1.0", "E = {Omega1 = 1.0, fibres = 5.0}")),
        2,
        "the cell group 'fibres' is named in [material]/[load], but the built-in unit-square mesh has only",
    ),
    Case(
        "case: a material group the mesh file lacks",
        _case(COMPOSITE.replace("fibres = 1e3", "fibers = 1e3")),
        2,
        "has no surface group 'fibers' (named in the case)",
    ),
    Case(
        "case: cells without a material",
        _case(COMPOSITE.replace("matrix = 1.0, ", "")),
        2,
        "material.E: 1113 cells lie in none of the groups given (['fibres'])",
    ),
    Case(
        "case: a traction on a group the unit square lacks",
        _case(SQUARE + "[boundary]\ntractions = {Gamma_N_side = [0.0, 1.0]}\n"),
        2,
        "boundary.tractions.Gamma_N_side: the mesh has no traction group 'Gamma_N_side'",
    ),
    Case(
        "case: a traction on a group the mesh file lacks",
        _case(COMPOSITE.replace("tractions = {", "tractions = {Gamma_N_bottom = [0.0, 1.0], ")),
        2,
        "a traction is given on the group 'Gamma_N_bottom', but the mesh has no facets",
    ),
    Case(
        "case: a traction group of the mesh without a traction",
        _case(COMPOSITE.replace("[boundary]\ntractions = {Gamma_N_top = [0.0, -0.01]}\n", "")),
        2,
        "the mesh has traction group(s) ['Gamma_N_top'] but the model gives no traction",
    ),
    Case(
        "case: Gamma_N overlapping Gamma_D (unit square)",
        _case(SQUARE.replace('clamped = ["left"]', 'clamped = ["left", "top"]\nneumann = {top = "Gamma_N_top"}')),
        2,
        "mesh.neumann: side 'top' is also in mesh.clamped",
    ),
    Case(
        "case: Gamma_N overlapping Gamma_D (mesh file)",
        _case_mesh(
            _MATERIAL + "[boundary]\ntractions = {Gamma_N_load = [0.0, -1.0]}\n", curve_groups={"Gamma_N_load": ("t0",)}
        ),
        2,
        "'Gamma_D' and 'Gamma_N_load' share 3 segments",
    ),
    Case(
        "case: an obstacle and no Gamma_C",
        _case_mesh(_MATERIAL + PLANE, gamma_c=()),
        2,
        "lacks the physical group(s) ['Gamma_C']",
    ),
    Case(
        "case: the gap undefined at a contact node",
        _case(SQUARE + '[obstacle]\nshape = "circle"\ncentre = [1.0, 0.5]\nradius = 0.2\n'),
        2,
        "the obstacle's gap is undefined at 1 contact node(s) of Gamma_C",
    ),
    Case(
        "case: a plane obstacle with its normal flipped (the body inside it)",
        _case(SQUARE + PLANE.replace("normal = [-1.0, 0.0]", "normal = [1.0, 0.0]")),
        2,
        "the obstacle is on the wrong side of Gamma_C",
    ),
    Case(
        "case: no side clamped",
        _case(SQUARE.replace('clamped = ["left"]', "clamped = []")),
        2,
        "mesh.clamped = [] leaves no Gamma_D: nothing holds the body",
    ),
    Case(
        "case: indentation of the flush wall",
        _case(SQUARE + "[obstacle]\nindentation = 0.01\n"),
        2,
        "obstacle.indentation moves a plane, a circle or a sphere",
    ),
    Case(
        "case: a circle's indentation with no direction",
        _case(SQUARE + '[obstacle]\nshape = "circle"\ncentre = [1.5, 0.5]\nradius = 0.5\nindentation = 0.01\n'),
        2,
        "obstacle.direction is required with obstacle.indentation for a circle",
    ),
    Case(
        "case: a 2-vector body force on the unit cube",
        _case(CUBE + "[load]\nbody-force = [1.0, 0.0]\n"),
        2,
        'load.body-force has 2 components but the mesh (builtin = "unit-cube") is 3D (tetrahedra): give 3',
    ),
    Case(
        "case: a 3-vector plane on the unit square",
        _case(SQUARE + PLANE.replace("point = [1.0, 0.0]", "point = [1.0, 0.0, 0.0]")),
        2,
        'obstacle.point has 3 components but the mesh (builtin = "unit-square") is 2D (triangles): give 2',
    ),
    Case(
        "case: a circle on the unit cube",
        _case(CUBE + '[obstacle]\nshape = "circle"\ncentre = [1.5, 0.5]\nradius = 0.5\n'),
        2,
        'obstacle.shape = "circle" is a 2D obstacle but the mesh (builtin = "unit-cube") is 3D (tetrahedra): '
        'give shape = "sphere"',
    ),
    Case(
        "case: a sphere on the unit square",
        _case(SQUARE + '[obstacle]\nshape = "sphere"\ncentre = [1.5, 0.5, 0.0]\nradius = 0.5\n'),
        2,
        'obstacle.shape = "sphere" is a 3D obstacle but the mesh (builtin = "unit-square") is 2D',
    ),
    Case(
        "case: a 3D model on the unit square",
        _case(SQUARE.replace("nu = 0.0", "nu = 0.0\nmodel = 5")),
        2,
        'material.model = 5 is a 3D model but the mesh (builtin = "unit-square") is 2D (triangles)',
    ),
    Case(
        "case: vectors of two dimensions with a mesh file",
        _case(COMPOSITE.replace("[boundary]", "[load]\nbody-force = [0.0, 0.0, 1.0]\n[boundary]")),
        2,
        "load.body-force has 3 components but boundary.tractions.Gamma_N_top has 2",
    ),
    Case(
        "case: a 3-vector traction on a planar mesh file",
        _case(COMPOSITE.replace("[0.0, -0.01]", "[0.0, -0.01, 0.0]")),
        2,
        "boundary.tractions.Gamma_N_top has 3 components but the mesh file composite.msh is 2D (triangles)",
    ),
    Case(
        "case: a bad run option",
        _case(SQUARE + "[run]\ntol = 0\n"),
        2,
        "[run] the relative tolerance must lie in (0, 1)",
    ),
    Case(
        "case: a run option of the wrong type",
        _case(SQUARE + '[run]\ntol = "small"\n'),
        2,
        "run.tol must be a number, got 'small'",
    ),
    Case(
        "case: a method option in [run]",
        _case(SQUARE + "[run]\ndelta = 1e-6\n"),
        2,
        "unknown key 'run.delta' (delta belongs in [primal])",
    ),
    Case(
        "case: a bad option in the table of a method not run",
        _case(SQUARE + "[mixed]\nepsilon = -1\n"),
        2,
        "[mixed] --epsilon (the mixed penalty ε) must be a finite number > 0",
    ),
    Case(
        "case: --h on the Hertz block",
        lambda tmp: ["--case", str(CASES_DIR / "hertz.toml"), "--h", "16"],
        2,
        "unknown key 'mesh.h' for builtin = \"hertz-block\"",
    ),
    Case(
        "case: a multiscale method on a mesh without a coarse grid",
        lambda tmp: ["--case", str(CASES_DIR / "hertz.toml"), "--set", "mesh.refinement=0.25", "--method", "primal-ms"],
        2,
        "has no coarse grid",
    ),
    Case(
        "case: Algorithm 3 on coarse cubes smaller than the cells",
        lambda tmp: [
            "--case",
            str(CASES_DIR / "sphere_3d.toml"),
            "--set",
            "mesh.refinement=0.2",
            "--set",
            "mesh.coarse-size=0.2",
            "--method",
            "primal-ms",
        ],
        2,
        "are smaller than the Omega1 cells",
    ),
    Case(
        "case: Algorithm 3 with strips that take a whole body",
        lambda tmp: ["--case", str(CASES_DIR / "two_blocks.toml"), "--set", "primal.layers=8", "--method", "primal-ms"],
        2,
        "take the whole body, no bulk is left",
    ),
    Case("all modes for mixed-ms", _args("--method", "mixed-ms", "--nbasis", "all"), 2, "apply to primal-ms"),
    Case(
        "a mixed method on the 3D model",
        lambda tmp: ["--model", "4", "--h", "8", "--method", "mixed"],
        2,
        "--method mixed solves plane problems (triangles) only and --model 4 is 3D",
    ),
    Case("--set without --case", _args("--set", "mesh.h=8"), 2, "--set changes a key of a case file"),
    Case(
        "case: bulged square finer than the memory",
        _case('[mesh]\nbuiltin = "bulged-square"\nh = 1000000\nH = 4\n' + _MATERIAL),
        2,
        "the bulged square with h = 1e-06 has about 1.32e+12 vertices and would need about",
    ),
    Case(
        "--method mixed on a mesh beyond the memory",
        lambda tmp: ["--h", "2048", "--H", "8", "--method", "mixed"],
        2,
        "the mesh of --method mixed has about 4.2e+06 vertices and would need about",
    ),
    Case(
        "--h far beyond the memory",
        lambda tmp: ["--h", "100000", "--H", "4"],
        2,
        "the mesh of --method primal has about 1e+10 vertices and would need about",
    ),
    Case(
        "the cube of the 3D model beyond the memory",
        lambda tmp: ["--model", "4", "--h", "400", "--H", "4"],
        2,
        "the mesh of --method primal has about 6.45e+07 vertices and would need about",
    ),
    # numbers out of range and numerical failure
    Case("E = 1e308 (overflow)", _args("--E-high", "1e308"), 2, "Rescale the units"),
    # δ = 1e-3·h/E_high given: the default takes E_c on Gamma_C, which the channels of model 1 do not reach at H = 1/4
    Case(
        "contrast 1e100 (beyond double precision)",
        _args("--E-high", "1e100", "--delta", "6.25e-105"),
        4,
        "numerical failure: fc_primal_omega2: semismooth Newton did not converge",
    ),
    # ε 6e6 times below the default: the saddle-point solves lose digits in proportion to 1/ε, and the Newton
    # and UFL residual checks miss their tolerance by ~10³ (serial, 2 ranks, models 1 and 2); near ε = 1e-8
    # (6e3 times below) the same checks pass or fail by round-off (0.86 to 1.8 times the tolerance)
    Case(
        "mixed with ε millions of times below its default (ill-conditioned reference)",
        _args("--method", "mixed", "--epsilon", "1e-11", "--reference"),
        4,
        "times below the default 1e-3·(h/L)·E_min/L",
    ),
]


def run_case(case: Case, tmp: Path, capsys) -> tuple[int, str, str]:
    """(exit code, stdout, stderr) of ``fenics-contact run`` on the case."""
    args = case.prepare(tmp)
    if "--out" not in args:
        args += ["--out", str(tmp / "out")]
    code = main(["run", "--no-plots", *args])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


@pytest.mark.parametrize("case", CASES, ids=[c.name for c in CASES])
def test_bad_input_table(case, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    code, out, err = run_case(case, tmp_path, capsys)
    lines = outcome_lines(err)
    assert code == case.code, err
    assert len(lines) == 1 and case.message in lines[0], err
    assert lines[0].startswith("numerical failure: " if code == 4 else "error: ")
    assert "Traceback" not in out + err
    assert not (tmp_path / "out").exists(), "nothing may be written"
    assert not list(tmp_path.glob(".fenics-contact-*")), "no staging directory may be left"


def test_epsilon_hint_only_far_below_the_default():
    """The hint every numerical failure of the mixed monolithic solve carries: only for ε < 1e-3 × the default."""
    assert epsilon_hint(1e-7, 6.25e-5) == ""  # 625 times below: no hint
    assert "; ε = 1e-11 is 6e+06 times below the default 1e-3·(h/L)·E_min/L = 6.25e-05" in epsilon_hint(1e-11, 6.25e-5)


def test_argparse_errors_exit_2(capsys):
    with pytest.raises(SystemExit) as info:
        main(["run", "--model", "6"])
    assert info.value.code == 2 and "invalid choice" in capsys.readouterr().err


def test_not_converged_is_exit_3_with_results(tmp_path, capsys):
    out = tmp_path / "capped"
    assert main(["run", *SMALL, "--accel", "none", "--max-iterations", "3", "--no-plots", "--out", str(out)]) == 3
    err = outcome_lines(capsys.readouterr().err)
    assert len(err) == 1 and err[0].startswith("not converged: the iteration hit --max-iterations 3"), err
    assert json.loads((out / "summary.json").read_text())["converged"] is False
