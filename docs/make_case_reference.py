"""The key reference of the case files, made from the code that reads them (called by ``conf.py`` at each build).

The set of keys of every table is taken from the package itself: a case with an unknown key in a table is
refused with a message that lists the keys that table accepts (``problem.case.load_case`` for the problem
tables, ``cli.case_run_options`` for the run tables), and that list is what this script tabulates, for each
variant of a table (each ``[mesh] builtin``, each ``[obstacle] shape``). The defaults of the mesh keys are the
fields of the mesh specifications (``problem.case.UnitSquareMesh``, ...); the type, default and meaning of a run
key are its ``cli.RunOptions`` field and its ``fenics-contact run`` flag's help. The meaning of a problem key is
written below, in ``PROBLEM_KEYS``; a key the code accepts and ``PROBLEM_KEYS`` does not describe (or the
reverse) fails the build, so the table cannot drift from the code.

    python docs/make_case_reference.py     # prints the Markdown (the build writes user_guide/generated/case_keys.md)
"""

import dataclasses
import re
import tempfile
import typing
from pathlib import Path

from fenics_contact import cli
from fenics_contact.errors import InputError
from fenics_contact.hybrid.two_body import TwoBodyHybridOptions
from fenics_contact.multiscale.cem import CEMOptions
from fenics_contact.problem import case as case_module
from fenics_contact.problem import case_meshes3d

ROOT = Path(__file__).resolve().parent.parent

#: the variants of the problem tables: (table, variant label, the case text that selects the variant,
#: the mesh specification whose fields give the defaults)
VARIANTS = [
    ("mesh", 'builtin = "unit-square"', '[mesh]\nbuiltin = "unit-square"\n', case_module.UnitSquareMesh),
    ("mesh", 'builtin = "hertz-block"', '[mesh]\nbuiltin = "hertz-block"\na = 1.0\n', case_module.HertzBlockMesh),
    ("mesh", 'builtin = "bulged-square"', '[mesh]\nbuiltin = "bulged-square"\n', case_module.BulgedSquareMesh),
    ("mesh", 'builtin = "unit-cube"', '[mesh]\nbuiltin = "unit-cube"\n', case_meshes3d.UnitCubeMesh),
    (
        "mesh",
        'builtin = "hertz-quarter-block"',
        '[mesh]\nbuiltin = "hertz-quarter-block"\na = 1.0\n',
        case_meshes3d.HertzQuarterBlockMesh,
    ),
    ("mesh", 'builtin = "fibre-block"', '[mesh]\nbuiltin = "fibre-block"\n', case_meshes3d.FibreBlockMesh),
    ("mesh", 'file = "..."', f'[mesh]\nfile = "{ROOT / "cases" / "pad.msh"}"\n', case_module.MeshFile),
    ("material", "", "[material]\nE = 1.0\nnu = 0.3\n", None),
    ("load", "", "[load]\n", None),
    ("boundary", "", "[boundary]\n", None),
    ("obstacle", 'shape = "wall"', "[obstacle]\n", None),
    ("obstacle", 'shape = "plane"', '[obstacle]\nshape = "plane"\npoint = [1.0, 0.0]\nnormal = [-1.0, 0.0]\n', None),
    ("obstacle", 'shape = "circle"', '[obstacle]\nshape = "circle"\ncentre = [2.0, 0.5]\nradius = 1.0\n', None),
    (
        "obstacle",
        'shape = "sphere"',
        '[obstacle]\nshape = "sphere"\ncentre = [1.5, 0.5, 0.5]\nradius = 0.5\n',
        None,
    ),
    ("friction", 'law = "coulomb"', '[friction]\nlaw = "coulomb"\nmu = 0.3\n', None),
    ("friction", 'law = "tresca"', '[friction]\nlaw = "tresca"\nthreshold = 0.01\n', None),
]

_SIDES = "a list of `left`, `bottom`, `top` (2D); of `xmin`, `ymin`, `ymax`, `zmin`, `zmax` (unit cube)"
#: (table, key) -> (type, default or None (taken from the mesh specification), meaning)
PROBLEM_KEYS = {
    ("mesh", "builtin"): (
        "string",
        "—",
        "a built-in mesh: `unit-square` (the paper's (0,1)², Γ_C at x = 1), "
        "`hertz-block` (a block under a cylinder, graded towards the contact), `bulged-square` "
        "(the unit square with a curved contact side); in 3D (tetrahedra) `unit-cube` ((0,1)³, Γ_C at x = 1), "
        "`hertz-quarter-block` (the quarter block under a sphere, its symmetry planes x = 0, y = 0 on rollers) "
        "or `fibre-block` (the block of model 5 with its cell groups `fibres` and `matrix`, Γ_C at x = 1, "
        "clamped at x = 0); exactly one of `builtin` and `file`",
    ),
    ("mesh", "file"): (
        "file name",
        "—",
        "a gmsh `.msh` file of planar triangles or of tetrahedra (relative to the case file): physical "
        "groups `Gamma_C`, `Gamma_D`, optionally `Gamma_N*` and material groups (surface groups in 2D, "
        "volume groups in 3D), and either all of `Omega1`, `Omega2`, `gamma` or none (the strip Ω₂ and γ "
        "are then built along Γ_C)",
    ),
    ("mesh", "h"): (
        "integer ≥ 2",
        None,
        "1/h, the fine mesh size (a multiple of 1/H; on the fibre block the size away from the contact)",
    ),
    ("mesh", "H"): (
        "integer",
        None,
        "1/H: the coarse grid of squares of side 1/H (the width of the strip Ω₂ of "
        "the unit square, cube and fibre block, and the side of their coarse squares or cubes; with `file`, the "
        "coarse grid over the bounding box that the multiscale methods use and, without Omega1/Omega2/gamma in the "
        "file, the strip width; on tetrahedra the coarse cells of `primal-ms` are the cubes that hold the Ω₁ "
        "cells' centroids)",
    ),
    ("mesh", "coarse-size"): (
        "number > 0",
        None,
        "with `file`: the coarse size H itself, a length in the mesh's units (instead of `H` = 1/H); with "
        "`hertz-quarter-block`: the side of the coarse cubes of `primal-ms`, in multiples of a (at most `size`/2; "
        "none: no coarse grid). Algorithm 3 in 3D refuses cubes smaller than the median Ω₁ cell or longer than "
        "half the body",
    ),
    ("mesh", "clamped"): (
        _SIDES,
        None,
        "the sides in Γ_D (u = 0, or `boundary.displacement`); the other sides without a traction are traction free",
    ),
    ("mesh", "neumann"): (
        'table `{side = "Gamma_N_<label>"}`',
        "{}",
        "sides (faces of the cube) that carry a traction group (its traction in `boundary.tractions`)",
    ),
    ("mesh", "a"): (
        "number > 0",
        "required",
        "the expected contact half-width (radius under a sphere); the block and the cell sizes are multiples of it",
    ),
    ("mesh", "refinement"): ("number > 0", None, "r: contact cells of size a/(20 r)"),
    ("mesh", "width"): ("number > 0", None, "the block's width, in multiples of a"),
    ("mesh", "depth"): ("number > 0", None, "the block's depth, in multiples of a"),
    ("mesh", "strip"): ("number > 0", None, "the depth of the strip Ω₂ below the top face, in multiples of a"),
    ("mesh", "size"): ("number > 2", None, "the side of the quarter block, in multiples of a"),
    ("mesh", "contact-size"): (
        "number > 0",
        "1/h",
        "the cell size within `contact-radius` of the middle of Γ_C (at most 1/h; it grows to 1/h over as far again)",
    ),
    ("mesh", "contact-radius"): ("number in (0, 1)", None, "the radius of the refined ball about the middle of Γ_C"),
    ("mesh", "contact-width"): ("number > 0", None, "Γ_C is the top segment \\|x\\| ≤ contact-width·a"),
    ("mesh", "bulge"): ("number in (0, ½)", None, "how far the circular arc of Γ_C bulges out at y = ½"),
    ("material", "E"): (
        "number, table by group, pixel map or python",
        "required (or `model`)",
        "Young's modulus: a number; `{group = value, ...}` by cell group (`Omega1`, `Omega2`, the "
        "fibre block's `fibres` and `matrix`, or the mesh file's surface groups, volume groups in 3D); "
        '`{pixels = "E.npy", extent = [x0, x1, y0, y1]}` (2D: a 2D array, '
        "row 0 at the bottom, `.npy` or text/`.csv`; extent default the bounding box); "
        '`{python = "file.py:name"}` (a callable x (3, N) → (N,))',
    ),
    ("material", "nu"): ("as `E`", "required (or `model`)", "the Poisson ratio, in (−1, ½), in the same forms"),
    ("material", "model"): (
        "1, 2 or 3; 4 or 5 (3D)",
        "—",
        "the E, ν and body force of a built-in test model (4, 5: of a 3D mesh; not their boundary conditions)",
    ),
    ("material", "E-high"): ("number > 0", "1e3", "with `model`: E in the high-modulus pattern"),
    ("material", "E-low"): ("number > 0", "1", "with `model`: E elsewhere"),
    ("load", "body-force"): (
        "vector, table by group or python",
        "0",
        "the body force f: `[fx, fy]` (`[fx, fy, fz]` in 3D), "
        "`{group = [fx, fy], ...}` (0 on cells in no group given) or "
        '`{python = "file.py:name"}` (x (3, N) → (d, N))',
    ),
    ("boundary", "displacement"): (
        "vector or python",
        "clamped",
        'u on Γ_D: `[ux, uy]` (`[ux, uy, uz]` in 3D) or `{python = "file.py:name"}`',
    ),
    ("boundary", "tractions"): (
        "table `{Gamma_N_<label> = [tx, ty] or {python = ...}}`",
        "{}",
        "σn on each traction group (3-vectors in 3D); every traction group of the mesh needs one",
    ),
    ("boundary", "rollers"): (
        "table `{axis = [values]}`",
        "{}",
        "symmetry planes on rollers: `{z = [0.0, 1.0]}` holds u_z = 0 on the boundary facets in the planes z = 0 "
        "and z = 1 (the primal methods in 3D); the hertz-quarter-block's own planes x = 0, y = 0 are added",
    ),
    ("obstacle", "shape"): (
        '`"wall"`, `"plane"`, `"circle"` or `"sphere"`',
        '"wall"',
        "the rigid obstacle: a wall flush with Γ_C (zero gap), a half-plane (half-space in 3D), a disc (a "
        "cylinder in plane strain; 2D) or a ball (3D)",
    ),
    ("obstacle", "point"): ("vector", "required", "a point of the plane (every vector of a case has the mesh's d)"),
    ("obstacle", "normal"): ("vector ≠ 0", "required", "the plane's outward normal, pointing towards the body"),
    ("obstacle", "centre"): ("vector", "required", "the centre of the circle or sphere (outside the body)"),
    ("obstacle", "radius"): ("number > 0", "required", "the radius of the circle or sphere"),
    ("obstacle", "indentation"): (
        "number or list of numbers",
        "none",
        "a depth by which the obstacle is moved "
        "along `direction`; a list is a sequence of load steps (a force–indentation "
        "curve); the run's fields are those of the last depth; not for the wall",
    ),
    ("obstacle", "direction"): (
        "vector ≠ 0",
        "the plane's normal",
        "the direction the obstacle moves in (normalized); required for a circle or sphere with `indentation`",
    ),
    ("obstacle", "motion"): (
        "list of vectors",
        "none",
        "rigid displacements of the obstacle from where the case places it, one per load step (press, then "
        "drag: a sliding path, the summary's `sliding`); the run's fields are those of the steps; instead of "
        "`indentation`; not for the wall",
    ),
    ("friction", "law"): (
        '`"coulomb"` or `"tresca"`',
        "required",
        "the friction law on Γ_C (without `[friction]`: frictionless); every method (the mixed ones in 2D)",
    ),
    ("friction", "mu"): ("number ≥ 0", "required", "the Coulomb coefficient: slip threshold μ times the pressure"),
    ("friction", "threshold"): ("number ≥ 0", "required", "the Tresca slip threshold s (a traction) on all of Γ_C"),
    ("friction", "stiffness-ratio"): (
        "number > 0",
        "1",
        "the stick stiffness 1/δ_t over the normal penalty 1/δ (the elastic stick slip it leaves is τ·δ_t); "
        "the mixed methods' slip penalty is ε_t = ε/ratio",
    ),
}

#: run keys whose flag's help does not say what the key does in a case file: key -> (default, meaning)
RUN_NOTES = {
    "plots": ("true", "write the PNG figures (the flag `--no-plots` sets it false)"),
    "max-iterations": (
        "2000",
        "the most iterations of the hybrid method; a run that reaches it unconverged "
        'writes its results with `"converged": false` (exit 3)',
    ),
    "coarse-groups": (
        "false",
        "not with a case file (refused): a case file's surface groups are material "
        "groups; its coarse grid is `mesh.H` or `mesh.coarse-size`",
    ),
    "out": (
        "`results/<case>-<method>`",
        "the output directory (relative to the working directory); replaced "
        "whole by the run, so it must be new, empty or an earlier run's",
    ),
}

TABLES = {
    "mesh": "the mesh (required)",
    "material": "the materials",
    "load": "the body force",
    "boundary": "the boundary conditions on Γ_D and Γ_N",
    "obstacle": "the rigid obstacle and its load steps",
    "friction": "the friction law on Γ_C",
}


def accepted_keys(text: str) -> tuple[str, list[str]]:
    """(table, its keys) from the message with which the package refuses an unknown key ``zz`` in ``text``'s
    last table."""
    with tempfile.TemporaryDirectory() as directory:
        path = Path(directory) / "probe.toml"
        mesh = "" if text.startswith("[mesh]") else '[mesh]\nbuiltin = "unit-square"\n'
        material = "" if "[material]" in text else "[material]\nE = 1.0\nnu = 0.3\n"
        path.write_text(mesh + material + text + "zz = 1\n")
        try:
            cli.case_run_options(case_module.load_case(path))
        except InputError as error:
            found = re.search(r"the keys of \[([\w-]+)\] are \[(.*?)\]", str(error))
            if found:
                return found.group(1), re.findall(r"'([\w-]+)'", found.group(2))
            raise
    raise RuntimeError(f"the package accepted the unknown key zz in {text!r}")


def _default(spec, key: str) -> str:
    field = next(f for f in dataclasses.fields(spec) if f.name == key.replace("-", "_"))
    if field.default is dataclasses.MISSING:
        return "required"
    value = field.default
    if value is None:
        return "none"
    if isinstance(value, tuple):
        return "[" + ", ".join(f'"{v}"' if isinstance(v, str) else str(v) for v in value) + "]" if value else "{}"
    return repr(value) if isinstance(value, str) else f"{value:g}"


def _row(key: str, kind: str, default: str, meaning: str) -> str:
    return f"| `{key}` | {kind} | {default} | {meaning} |"


def problem_tables() -> str:
    seen, blocks = set(), []
    for table, variant, text, spec in VARIANTS:
        found, keys = accepted_keys(text)
        assert found == table, (found, table)
        rows = []
        for key in keys:
            if (table, key) not in PROBLEM_KEYS:
                raise KeyError(f"[{table}] accepts the key {key!r}, which PROBLEM_KEYS does not describe")
            seen.add((table, key))
            kind, default, meaning = PROBLEM_KEYS[table, key]
            if default is None:
                default = _default(spec, key)
            rows.append(_row(key, kind, default, meaning))
        title = f"`[{table}]` with `{variant}`" if variant else f"`[{table}]`: {TABLES[table]}"
        blocks.append(f"### {title}\n\n| key | type | default | meaning |\n|---|---|---|---|\n" + "\n".join(rows))
    unused = sorted(set(PROBLEM_KEYS) - seen)
    if unused:
        raise KeyError(f"PROBLEM_KEYS describes keys the package does not accept: {unused}")
    return "\n\n".join(blocks)


def _run_actions() -> dict[str, object]:
    """dest -> the argparse action of ``fenics-contact run``."""
    parser = cli.build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")  # argparse has no public accessor
    return {action.dest: action for action in sub.choices["run"]._actions}


def _type(annotation) -> str:
    kinds = [t for t in (typing.get_args(annotation) or (annotation,)) if t is not type(None)]
    names = {bool: "boolean", int: "integer", float: "number", str: "string", Path: "directory name"}
    return " or ".join(names.get(kind, str(kind)) for kind in kinds)


def run_tables() -> str:
    actions = _run_actions()
    options = {f.name: f for f in dataclasses.fields(cli.RunOptions)}
    blocks = []
    for table, methods in cli.TABLE_METHODS.items():
        _, keys = accepted_keys(f"[{table}]\n")
        rows = []
        for key in keys:
            name = key.replace("-", "_")
            field = options[name]
            if key in RUN_NOTES:
                default, meaning = RUN_NOTES[key]
            else:
                action = actions[name]
                meaning = (action.help or "").replace("|", "\\|")
                if action.choices:
                    meaning += " (one of " + ", ".join(f"`{c}`" for c in action.choices) + ")"
                default = field.default
                default = (
                    "method's default"
                    if default is None
                    else str(default).lower()
                    if isinstance(default, bool)
                    else f"`{default}`"
                    if isinstance(default, str)
                    else f"{default:g}"
                )
            rows.append(_row(key, _type(field.type), default, meaning))
        used = ", ".join(f"`{m}`" for m in methods)
        blocks.append(
            f"### `[{table}]`\n\nRead by {used}; each key is overridden by the command line's flag of "
            f"its name (`--{keys[0]}`, ...).\n\n| key | type | default | meaning |\n|---|---|---|---|\n"
            + "\n".join(rows)
        )
    return "\n\n".join(blocks)


#: the tables of a two-body case (one with ``[pair]``), each probed by an unknown key set with ``--set``:
#: (table as written in the case, the key the probe sets, what the table is)
PAIR_TABLES = [
    ("mesh", "mesh.zz", "the mesh file of both bodies (required) and the coarse size of `primal-ms`"),
    ("bodies.<name>", "bodies.lower.zz", "one body (two such tables, any names)"),
    ("supports entry", "bodies.lower.supports", "one entry of a body's `supports` list"),
    ("pair", "pair.zz", "the contact surfaces (required: it makes the case a two-body one)"),
    ("friction", "friction.zz", "friction on the relative slip of the two faces (default frictionless)"),
    ("load", "load.zz", "load steps: the displacement of one support, or one traction, step by step"),
    ("run", "run.zz", "the run (every method)"),
    ("primal", "primal.zz", 'the options of Algorithms 1 and 3 (`method = "primal"` and `"primal-ms"` only)'),
    ("multiscale", "multiscale.zz", 'the CEM-GMsFEM space of each bulk (`method = "primal-ms"` only)'),
]
#: (table, key) -> (type, default, meaning) of the two-body case keys
PAIR_KEYS = {
    ("mesh", "file"): (
        "file name",
        "required",
        "a gmsh `.msh` file of planar triangles (or tetrahedra) holding both bodies, meshed apart (no shared "
        "node); every cell in a surface (volume) group",
    ),
    ("mesh", "coarse-size"): (
        "number > 0",
        "required by `primal-ms`",
        "H, the side of the coarse squares of both bulks (mesh units): at least a fine cell, below half of each "
        "body's longer side",
    ),
    ("mesh", "H"): ("integer ≥ 1", "—", "1/H instead of `coarse-size` (the flag `--H`)"),
    ("bodies.<name>", "cells"): ("group name or list", "required", "the body's surface groups (e.g. its layers)"),
    ("bodies.<name>", "E"): (
        "number, `{group = value}`, `{python = ...}`",
        "required",
        "Young's modulus: one value, a value per cell group of the body, or a callable",
    ),
    ("bodies.<name>", "nu"): ("number in (−1, ½), by group, python", "required", "Poisson's ratio, the same forms"),
    ("bodies.<name>", "body-force"): ("vector `[fx, fy]` or python", "[0, 0]", "the body force"),
    ("bodies.<name>", "supports"): (
        "list of tables",
        "[]",
        "Dirichlet boundaries (each body needs one: contact does not hold it tangentially before it touches)",
    ),
    ("bodies.<name>", "tractions"): ("table `{group = [tx, ty]}`", "{}", "tractions σn = t on facet groups"),
    ("supports entry", "facets"): ("group name", "required", "the facet group held"),
    ("supports entry", "displacement"): ("vector or python", "[0, 0]", "the prescribed displacement u_D"),
    ("supports entry", "components"): (
        "list of 0, 1",
        "[0, 1]",
        "the components held (`[0]`: a roller holding x only)",
    ),
    ("pair", "slave"): ("group name", "required", "the slave surface Γ_C: the contact integral lives on it"),
    ("pair", "master"): ("group name", "required", "the master surface, onto which the slave points are projected"),
    ("pair", "quadrature-degree"): ("integer in [1, 10]", "3", "the Gauss rule on each slave segment"),
    ("pair", "rule"): (
        "`segments` or `vertices`",
        '"segments"',
        "segment-to-segment mortar gaps, or one-pass node-to-segment (fails the patch test: for comparison)",
    ),
    ("pair", "basis"): (
        "`dual` or `standard`",
        'dual (standard with `rule = "vertices"`)',
        "the pressure basis: the dual (biorthogonal) mortar basis or the P1 hat functions (`ContactPair.basis`)",
    ),
    ("friction", "law"): (
        "`coulomb` or `tresca`",
        "required",
        "the law, as for one body; `tresca` takes `threshold` (a traction, ≥ 0) in place of `mu`",
    ),
    ("friction", "mu"): ("number ≥ 0", "required", "the Coulomb coefficient: slip threshold μ times the pressure"),
    ("friction", "stiffness-ratio"): (
        "number > 0",
        "1",
        "the stick stiffness over the normal penalty 1/δ",
    ),
    ("load", "support"): (
        "group name",
        "—",
        "the facet group of the support whose displacement steps (one of `support` and `traction`)",
    ),
    ("load", "traction"): (
        "group name",
        "—",
        "a group of a body's `tractions` whose value steps (one of `support` and `traction`)",
    ),
    ("load", "steps"): (
        "list of vectors",
        "required",
        "its displacement (or traction) at each step; the last is the run's; each step starts from the last's solution "
        "(`primal-monolithic` on one process)",
    ),
    ("run", "method"): (
        "string",
        '"primal-monolithic"',
        "`primal-monolithic`, `primal` (Algorithm 1, a strip per side) or `primal-ms` (Algorithm 3: each bulk a "
        "CEM-GMsFEM space; one process, frictionless)",
    ),
    ("run", "out"): ("directory name", "`results/<case>-<method>`", "the output directory"),
    ("run", "plots"): ("boolean", "true", "write the PNG figures"),
    ("run", "delta"): (
        "number > 0",
        "10⁻³ h/E_c",
        "the contact penalty δ (h the median facet size of the surfaces, E_c the largest E at them)",
    ),
    ("primal", "tol"): ("number", None, "the transmission residual to reach"),
    ("primal", "max-iterations"): ("integer", None, "the most evaluations of the transmission map"),
    ("primal", "accel"): ("string", None, "the interface update: `newton`, `anderson` or `none`"),
    ("primal", "layers"): ("integer", None, "cell layers of each strip from its contact surface"),
    ("multiscale", "layers"): (
        "integer ≥ 0",
        str(CEMOptions().layers),
        "oversampling layers m of the bases (the flag `--layers`); enough to cover each bulk gives its global bases",
    ),
    ("multiscale", "nbasis"): (
        'integer ≥ 1, `"rigid"`, `"all"`',
        '"rigid"',
        "local modes per coarse cell (the flag `--nbasis`): the rigid motions (3), or every mode (with patches "
        "covering each bulk, Algorithm 1's solution)",
    ),
    ("primal", "alpha-scale"): ("number > 0", None, "α_p = alpha-scale · E_p / √(h_γ L_ref), L_ref the pair's size"),
}


def _pair_keys(probe: str) -> list[str]:
    """The keys the package accepts in a two-body table, from its refusal of ``probe`` = 1 (or ``[{zz = 1}]``)."""
    from fenics_contact.cli.pair import pair_run_options

    case_file = ROOT / "cases" / ("fault_sliding.toml" if probe.startswith("friction") else "two_blocks.toml")
    value = [{"facets": "lower_bottom", "zz": 1}] if probe.endswith("supports") else 1
    try:
        pair_run_options(case_module.load_case(case_file, [(probe, value)]))
    except InputError as error:
        found = re.search(r"the keys of \[[^\]]*\]* are \[(.*?)\]", str(error))
        if found:
            return re.findall(r"'([\w-]+)'", found.group(1))
        raise
    raise RuntimeError(f"the package accepted the unknown key {probe}")


def pair_tables() -> str:
    seen, blocks = set(), []
    for table, probe, what in PAIR_TABLES:
        rows = []
        for key in _pair_keys(probe):
            if (table, key) not in PAIR_KEYS:
                raise KeyError(f"[{table}] of a two-body case accepts {key!r}, which PAIR_KEYS does not describe")
            seen.add((table, key))
            kind, default, meaning = PAIR_KEYS[table, key]
            if default is None:  # Algorithm 1's options: the defaults of its options dataclass
                default = _default(TwoBodyHybridOptions, key)
            rows.append(_row(key, kind, default, meaning))
        title = f"`[{table}]`" if table != "supports entry" else "an entry of `supports`"
        blocks.append(
            f"### {title}: {what}\n\n| key | type | default | meaning |\n|---|---|---|---|\n" + "\n".join(rows)
        )
    unused = sorted(set(PAIR_KEYS) - seen)
    if unused:
        raise KeyError(f"PAIR_KEYS describes keys the package does not accept: {unused}")
    return "\n\n".join(blocks)


def markdown() -> str:
    return (
        "## The problem tables\n\n"
        + problem_tables()
        + "\n\n## The run tables\n\n"
        + run_tables()
        + "\n\n## Two-body cases\n\n"
        + pair_tables()
        + "\n"
    )


if __name__ == "__main__":
    print(markdown())
