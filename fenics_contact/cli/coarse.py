"""The coarse grid of the multiscale methods checked before a run: every Ω₁ cell in a coarse cell of the mesh.

A mesh records whether its coarse cells are squares (cubes) of side H or a partition of any other shape
(``ContactMesh.coarse_grid``).  In the plane the squares of side H are those the mesh resolves.  On a mesh of
tetrahedra the cubes of side H are the grid's or those that hold the Ω₁ cells' centroids
(``strip.omega1_coarse_cells``); a run of Algorithm 3 there is refused when a coarse cell would hold less than a fine
cell (H below the median diameter of the Ω₁ cells) or Ω₁ would be less than two coarse cells long (H above half the
body's longest side).  Any other partition (the graded boxes of ``partition.graded_coarse_cells``, the user's groups)
is checked to cover Ω₁ with two or more coarse cells larger than the fine cells they hold.
"""

import math

import numpy as np
from mpi4py import MPI

from fenics_contact.cli.options import RunOptions
from fenics_contact.errors import InputError
from fenics_contact.problem.case import Case
from fenics_contact.problem.geometry import ContactMesh
from fenics_contact.problem.partition import coarse_to_fine, simplex_volumes
from fenics_contact.problem.tags import Subdomain

__all__ = ["check_case_coarse_grid", "check_coarse_cells", "check_coarse_grid"]

#: the key of a 3D case's coarse size, by built-in mesh (a mesh file: mesh.coarse-size or mesh.H)
_CASE_KEYS = {
    "unit-cube": "mesh.H, 1/H: the strip and the coarse cubes",
    "fibre-block": "mesh.H, 1/H: the strip and the coarse cubes",
    "hertz-quarter-block": "mesh.coarse-size, in multiples of a",
}


def check_coarse_grid(cm: ContactMesh, options: RunOptions) -> None:
    """The multiscale methods need the coarse grid of squares of side H to be a union of fine cells (in 3D, or on
    a partition that is not squares: ``check_coarse_cells``)."""
    where = f"--method {options.method} with --mesh {options.mesh}"
    if cm.mesh.topology.dim == 3:
        source = f"--mesh {options.mesh}" if options.mesh is not None else f"--model {options.model}"
        missing = (
            f"a 3D mesh file gets its coarse grid (cubes of side 1/--H) when it runs with a multiscale method: "
            f"check it with check-mesh {options.mesh} --method primal-ms --H N"
        )
        check_coarse_cells(cm, f"--method {options.method} with {source}", "--H (1/H)", missing)
        return
    if not cm.coarse_grid or cm.H is None:  # (the user's coarse cells, or none)
        check_coarse_cells(cm, where, "--H", "give --H (1/H: the coarse squares) or the coarse cells' groups")
        return
    _check_squares(cm, where, f"1/{options.H} over the bounding box", "--H")


def check_case_coarse_grid(cm: ContactMesh, options: RunOptions, case: Case) -> None:
    """The multiscale methods need a coarse grid that the case's mesh resolves."""
    where = f"--method {options.method} with case {case.path.name}"
    if cm.mesh.topology.dim == 3:
        key = _CASE_KEYS.get(case.mesh.kind, "mesh.coarse-size, a length, or mesh.H, 1/H")
        check_coarse_cells(cm, where, key, f"give {key}: the side of the coarse cubes")
        return
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
    if not cm.coarse_grid:
        check_coarse_cells(cm, where, "mesh.H", "give mesh.H (1/H: the coarse squares)")
        return
    _check_squares(cm, where, f"{cm.H:g} from the origin", "mesh.H")


def _check_squares(cm: ContactMesh, where: str, grid: str, key: str) -> None:
    """InputError (starting with ``where``) when Ω₁ cells of the plane mesh ``cm`` cross the edges of its coarse
    grid of squares (of side ``grid``; ``key`` sets it). Collective."""
    cells = cm.cell_tags.find(Subdomain.OMEGA1)
    crossing = cm.comm.allreduce(int(np.count_nonzero(cm.coarse_cell[cells] < 0)), op=MPI.SUM)
    if crossing:
        raise InputError(
            f"{where}: {crossing} Omega1 cells cross the edges of the coarse grid of squares of side {grid}; the "
            f"multiscale methods need a mesh that resolves it (choose {key} accordingly)"
        )


def check_coarse_cells(cm: ContactMesh, where: str, key: str, missing: str) -> None:
    """InputError (starting with ``where``) unless every Ω₁ cell of ``cm`` (a mesh of tetrahedra, or one whose
    coarse cells are not squares) lies in a coarse cell and the coarse cells are of a size Algorithm 3 can use
    (``key``: the option that sets it; ``missing``: what to do when the mesh has no coarse grid).  Cubes of side H
    (``cm.coarse_grid``): H at least the median diameter of the Ω₁ cells and at most half of the body's longest
    side.  Any other partition (graded boxes, the user's groups): at least two coarse cells in Ω₁, larger than the fine
    cells they hold (the median over the coarse cells K of |K|^(1/d) over the mean (d!|T|)^(1/d) of their cells at
    least 1).  Collective."""
    comm = cm.comm
    d = cm.mesh.topology.dim
    cells = cm.cell_tags.find(Subdomain.OMEGA1)
    cells = cells[cells < cm.mesh.topology.index_map(d).size_local]
    coarse = np.asarray(cm.coarse_cell)[cells]
    if comm.allreduce(int(np.count_nonzero(coarse >= 0)), op=MPI.SUM) == 0:
        raise InputError(f"{where}: the mesh has no coarse grid of Omega1 for Algorithm 3; {missing}")
    outside = comm.allreduce(int(np.count_nonzero(coarse < 0)), op=MPI.SUM)
    if outside:
        raise InputError(
            f"{where}: {outside} Omega1 cells lie in no coarse cell of the mesh's partition; give every Omega1 cell "
            f"a coarse cell, or a coarse size ({key})"
        )
    if not cm.coarse_grid:
        held = np.unique(np.concatenate(comm.allgather(np.unique(coarse)))).size
        if held < 2:
            raise InputError(
                f"{where}: Omega1 is one coarse cell of the mesh's partition; Algorithm 3 needs at least two coarse "
                f"cells in it; give a coarse size ({key})"
            )
        ratio = _size_ratio(cm, cells, coarse)
        if ratio < 1.0:
            raise InputError(
                f"{where}: the coarse cells are smaller than the Omega1 cells they hold (the median over the "
                f"coarse cells of |K|^(1/{d}) over their cells' ({math.factorial(d)}|T|)^(1/{d}) is {ratio:.3g}): a "
                f"coarse cell must hold several fine cells; give a coarse size ({key})"
            )
        return
    diameters = np.concatenate(comm.allgather(cm.mesh.h(d, cells)))
    h = float(np.median(diameters))
    if cm.H is not None and cm.H < h:
        raise InputError(
            f"{where}: the coarse cubes of side H = {cm.H:.4g} are smaller than the Omega1 cells (median diameter "
            f"{h:.4g}): a coarse cell must hold several fine cells; give a larger coarse size ({key})"
        )
    x = cm.mesh.geometry.x
    side = max(
        comm.allreduce(float(top), op=MPI.MAX) - comm.allreduce(float(bottom), op=MPI.MIN)
        for bottom, top in zip(np.min(x, axis=0, initial=np.inf), np.max(x, axis=0, initial=-np.inf), strict=True)
    )
    if cm.H is not None and cm.H > side / 2 * (1 + 1e-12):
        raise InputError(
            f"{where}: the coarse size H = {cm.H:.4g} is more than half of the body's longest side ({side:.4g}): "
            f"Algorithm 3 needs at least two coarse cells along it; give a smaller coarse size ({key})"
        )


def _size_ratio(cm: ContactMesh, cells: np.ndarray, coarse: np.ndarray) -> float:
    """``partition.coarse_to_fine`` of the owned ``cells`` of the mesh and their ``coarse`` indices (over the ranks)."""
    d = cm.mesh.topology.dim
    volumes = simplex_volumes(cm.mesh.geometry.x[cm.mesh.geometry.dofmaps[0][cells]][:, :, :d])
    return coarse_to_fine(volumes, coarse, d, cm.comm)
