"""The coarse grid of the multiscale methods checked before a run: every Ω₁ cell in a coarse cell of the mesh."""

import numpy as np
from mpi4py import MPI

from fenics_contact.cli.options import RunOptions
from fenics_contact.errors import InputError
from fenics_contact.problem.case import Case
from fenics_contact.problem.geometry import ContactMesh
from fenics_contact.problem.tags import Subdomain

__all__ = ["check_case_coarse_grid", "check_coarse_grid"]


def check_coarse_grid(cm: ContactMesh, options: RunOptions) -> None:
    """The multiscale methods need the coarse grid of squares of side H to be a union of fine cells."""
    if cm.mesh.topology.dim == 3 and cm.H is None:
        raise InputError(
            f"--method {options.method} with --mesh {options.mesh}: a 3D mesh file has no coarse grid (--H sets "
            "only the strip there); primal-ms runs in 3D on the cube of --model 4 (its coarse cubes of side 1/H) or "
            "through the Python API on a mesh with a coarse partition (ContactMesh.coarse_cell)"
        )
    cells = cm.cell_tags.find(Subdomain.OMEGA1)
    crossing = cm.comm.allreduce(int(np.count_nonzero(cm.coarse_cell[cells] < 0)), op=MPI.SUM)
    if crossing:
        raise InputError(
            f"--method {options.method} with --mesh {options.mesh}: {crossing} Omega1 cells cross the "
            f"edges of the coarse grid of squares of side 1/{options.H} over the bounding box; the "
            "multiscale methods need a mesh that resolves it (choose --H accordingly)"
        )


def check_case_coarse_grid(cm: ContactMesh, options: RunOptions, case: Case) -> None:
    """The multiscale methods need a coarse grid that the case's mesh resolves."""
    if cm.mesh.topology.dim == 3:
        raise InputError(
            f"--method {options.method}: case {case.path.name} is 3D and a 3D case has no coarse grid of cubes "
            "(its H is the strip width); Algorithm 3 in 3D runs on --model 4 or from Python on a mesh with cubes "
            "(fc.unit_cube(n, H=...), fc.box_mesh(..., H=...)): use --method primal for the case"
        )
    if cm.H is None:
        builtin = case.mesh.kind in ("hertz-block", "bulged-square")
        raise InputError(
            f"--method {options.method}: the mesh of case {case.path.name} ({case.mesh.kind}) has no "
            "coarse grid; the multiscale methods need the unit-square mesh or a mesh file with mesh.H "
            "(a coarse grid of squares of side 1/H that the mesh resolves)"
            + (
                f" — the built-in {case.mesh.kind} mesh takes no mesh.H (its graded cells cross any "
                "such grid): use --method primal or mixed on it, or a mesh file of your own that a "
                "coarse grid resolves (mesh.H) or that carries its own coarse partition (README, 'Any "
                "domain')"
                if builtin
                else ""
            )
        )
    cells = cm.cell_tags.find(Subdomain.OMEGA1)
    crossing = cm.comm.allreduce(int(np.count_nonzero(cm.coarse_cell[cells] < 0)), op=MPI.SUM)
    if crossing:
        raise InputError(
            f"--method {options.method} with case {case.path.name}: {crossing} Omega1 cells cross the "
            f"edges of the coarse grid of squares of side {cm.H:g} from the origin; the multiscale "
            "methods need a mesh that resolves it (choose mesh.H accordingly)"
        )
