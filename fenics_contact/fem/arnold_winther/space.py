"""The Arnold–Winther space X_h ⊂ H(div; Ω; S) on a (distributed) mesh of affine triangles.

Forms are written on a discontinuous vector P3 space ``dg`` holding (σ_xx, σ_xy, σ_yy); the sparse
prolongation P maps AW coefficients to DG coefficients, so the AW operators are Pᵀ A P, B P, Pᵀ b.  The
space composes the mesh entities (``topology``), the local nodal bases (``local_basis``), the essential
conditions and traction lifting (``constraints``), the global numbering (``numbering``) and P
(``prolongation``).
"""

from __future__ import annotations

import time
from collections.abc import Callable

import basix.ufl
import dolfinx
import dolfinx.fem
import dolfinx.fem.petsc
import dolfinx.mesh
import numpy as np
import numpy.typing as npt
import scipy.sparse as sp
import ufl
from mpi4py import MPI
from petsc4py import PETSc

from fenics_contact.fem.arnold_winther.constraints import EssentialConstraints
from fenics_contact.fem.arnold_winther.functionals import NUM_LOCAL, dof_values
from fenics_contact.fem.arnold_winther.local_basis import local_nodal_basis
from fenics_contact.fem.arnold_winther.numbering import number_dofs
from fenics_contact.fem.arnold_winther.prolongation import Prolongation
from fenics_contact.fem.arnold_winther.shared_basis import shared_nodal_basis
from fenics_contact.fem.arnold_winther.tensors import symmetric_tensor
from fenics_contact.fem.arnold_winther.topology import TriangleEntities

__all__ = ["ArnoldWintherSpace"]


def _as_form(form) -> dolfinx.fem.Form:
    return form if isinstance(form, dolfinx.fem.Form) else dolfinx.fem.form(form)


class ArnoldWintherSpace:
    """Lowest-order Arnold–Winther stress space X_h ⊂ H(div; Ω; S) on a (distributed) triangle mesh.

    Forms are written on ``self.dg`` (DG P3, value shape (3,) = (σ_xx, σ_xy,
    σ_yy)); use :meth:`stress` to obtain the symmetric tensor and
    :meth:`assemble_matrix` / :meth:`assemble_vector` to obtain the AW
    operators Pᵀ A P, B P, Pᵀ b.

    **Numbering** (``numbering``).  The space numbers its degrees of freedom globally: each rank owns those
    of its owned vertices, edges and cells and learns the numbers of its ghosts from their owners.
    Essential constraints are gathered from all ranks (boundary data, small), so every rank forms the same
    constraint rows and null spaces at a vertex shared by ranks.  In serial the numbering is the raw one.

    Args:
        mesh: mesh of affine triangles, gdim 2 (serial or distributed).
        zero_tangential_facets: local facet (edge) indices of straight edges on which
            σn·t = 0 is imposed essentially (frictionless / sliding).
        zero_traction_facets: local facet indices on which σn = 0 is imposed
            essentially (traction-free).
        prescribed_tractions: pairs (facets, t) with facets among
            ``zero_traction_facets`` and t a callable x (3, N) -> (2, N): σn = t
            there (outward n), carried by the lifting ``lifting_dg``.
        split_interface: (facets, cells): at the vertices of these facets (γ) the
            stress gets extra functions living on ``cells`` only (one side of γ) whose
            normal trace on γ vanishes: σ_tt may differ on the two sides of a γ vertex.
        basis_comm: ranks that each hold this same serial mesh (a replicated Ω₁ of Algorithm 4) and
            share out the cells' nodal bases (``shared_nodal_basis``); the space is the same as without.
    """

    def __init__(
        self,
        mesh: dolfinx.mesh.Mesh,
        *,
        zero_tangential_facets: npt.ArrayLike | None = None,
        zero_traction_facets: npt.ArrayLike | None = None,
        prescribed_tractions: list | None = None,
        split_interface: tuple[npt.ArrayLike, npt.ArrayLike] | None = None,
        basis_comm: MPI.Comm | None = None,
    ) -> None:
        t0 = time.perf_counter()
        if mesh.topology.cell_type != dolfinx.mesh.CellType.triangle:
            raise ValueError(f"Arnold–Winther needs a triangle mesh, got {mesh.topology.cell_type}.")
        if mesh.geometry.dim != 2:
            raise ValueError("Arnold–Winther needs a mesh with geometric dimension 2.")
        if len(mesh.geometry.cmaps) != 1 or mesh.geometry.cmaps[0].degree != 1:
            raise ValueError("Arnold–Winther needs an affine (degree 1) geometry.")
        self.mesh = mesh
        self.comm = mesh.comm
        ent = self.entities = TriangleEntities(mesh)
        nc, nv, ne = ent.num_cells, ent.num_vertices, ent.num_edges
        self.num_cells, self.num_vertices, self.num_edges = nc, nv, ne

        # DG P3 space for (σ_xx, σ_xy, σ_yy)
        scalar = basix.ufl.element("DG", "triangle", 3)
        self.dg = dolfinx.fem.functionspace(mesh, basix.ufl.blocked_element(scalar, shape=(3,)))
        bel = scalar.basix_element
        ref_pts = np.asarray(bel.points)
        interp = np.asarray(bel.interpolation_matrix)  # (10, 10), identity for Lagrange

        # local AW -> full local numbering
        self.num_dofs_full = ent.num_dofs_full
        l2g = np.empty((nc, NUM_LOCAL), dtype=np.int64)
        l2g[:, 0:9] = (3 * ent.c2v[:, :, None] + np.arange(3)).reshape(nc, 9)
        l2g[:, 9:21] = (3 * nv + 4 * ent.c2e[:, :, None] + np.arange(4)).reshape(nc, 12)
        l2g[:, 21:24] = 3 * nv + 4 * ne + 3 * np.arange(nc)[:, None] + np.arange(3)

        # per-cell nodal basis at the DG nodes -> DG coefficients: the cells' blocks of the full P, each cell's
        # columns (AW numbers) increasing.  Read-only: the CSR P_full may share their memory.  The CSR matrices
        # P_full and P are made when first asked for (Algorithm 4's Ω₁ never asks: its cell operators read the
        # blocks, its interface maps the γ cells' rows, ``prolongation_for_rows``)
        order = np.argsort(l2g, axis=1, kind="stable")
        cell_cols = np.take_along_axis(l2g, order, axis=1)  # (nc, 24)
        vertices = ent.vx[ent.c2v]
        if basis_comm is not None and basis_comm.size > 1 and self.comm.size == 1:
            values = shared_nodal_basis(vertices, ent.edge_flip, ref_pts, basis_comm, column_order=order)
        else:
            values = local_nodal_basis(vertices, ent.edge_flip, ref_pts, column_order=order)  # (nc, 10, 3, 24)
        if not np.array_equal(interp, np.eye(interp.shape[0])):
            values = np.einsum("pq,nqjk->npjk", interp, values)
        cell_blocks = values.reshape(nc, 30, NUM_LOCAL)
        cell_blocks.flags.writeable = False
        del values
        dg_dofs = self.dg.dofmap.list[:nc].astype(np.int64)  # (nc, 10) blocks (owned: DG)
        rows = (3 * dg_dofs[:, :, None] + np.arange(3)).reshape(nc, 30)
        self._n_dg = 3 * self.dg.dofmap.index_map.size_local
        self.constraints = EssentialConstraints(
            ent, self.comm, zero_tangential_facets, zero_traction_facets, prescribed_tractions
        )
        #: stacked essential constraint rows (k, 3) acting on the vertex value σ(v), per constrained local vertex
        self.vertex_constraints: dict[int, np.ndarray] = self.constraints.vertex_constraints
        if split_interface is not None:
            self.constraints.split_interface(split_interface[0])
        self.numbering = num = number_dofs(ent, self.constraints, self.comm)
        self.num_owned, self.ghosts, self.ghost_owners = num.num_owned, num.ghosts, num.ghost_owners
        self.global_indices = num.global_indices
        split_cells = None
        if split_interface is not None and num.X_local is not None:
            cells = np.asarray(split_interface[1], dtype=np.int64)
            split_cells = cells[cells < nc]
        self.prolongator = Prolongation(
            self.comm, cell_blocks, cell_cols, rows, self._n_dg, self.num_dofs_full, num, split_cells
        )
        #: DG coefficients of the traction lifting σ_t (None without prescribed tractions)
        self.lifting_dg: np.ndarray | None = None
        #: local vertices where the prescribed tractions of two edges are incompatible (least-squares value used)
        self.incompatible_vertices: np.ndarray = np.zeros(0, dtype=np.int64)
        if prescribed_tractions:
            self.lifting_dg = self.prolongator.full @ self.constraints.lifting()
            self.incompatible_vertices = self.constraints.incompatible_vertices
        self.build_time = time.perf_counter() - t0

    def vertex_coordinates(self, vertices: npt.ArrayLike) -> np.ndarray:
        """Coordinates (N, 2) of local topology vertices."""
        return self.entities.vx[np.asarray(vertices, dtype=np.int64)]

    # -- public API ----------------------------------------------------------

    @property
    def num_dofs(self) -> int:
        """Global number of (reduced) AW degrees of freedom."""
        return int(self.numbering.offsets[-1])

    @property
    def global_vertex_indices(self) -> np.ndarray:
        """Global number of every local topology vertex (owned, then ghosts)."""
        return self.entities.vertex_gid

    @property
    def owned_range(self) -> tuple[int, int]:
        """(first, last + 1) global number of the DOFs this rank owns."""
        offs = self.numbering.offsets
        return int(offs[self.comm.rank]), int(offs[self.comm.rank + 1])

    @property
    def prolongation(self) -> sp.csr_matrix:
        """Local P (SciPy CSR): owned DG coefficients × local AW coefficients (owned, then ``ghosts``).

        In serial: AW coefficients -> coefficients of ``self.dg``.  Made when first asked for and kept
        (``release_prolongation`` drops it).
        """
        return self.prolongator.matrix

    def prolongation_for_rows(self, rows: npt.ArrayLike) -> sp.csr_matrix:
        """P where it has been made; else P's rows in the cells holding the given ``dg`` rows, the other rows
        empty (same shape): Q P = Q P_rows for any Q whose nonzero columns are among ``rows``.

        Row for row the same numbers as P (each row is formed from its own row of P_full); it costs only those
        cells (e.g. the interface maps of Algorithm 4's Ω₁: the γ cells, where P is never made).
        """
        return self.prolongator.for_rows(rows)

    def cell_prolongation(self) -> tuple[np.ndarray, np.ndarray]:
        """(cols (n, 24), blocks (n, 30, 24)): P_full's rows of each owned cell (``dg_rows`` order) at its AW
        columns, columns increasing (read-only arrays, kept by the space)."""
        return self.prolongator.cell_cols, self.prolongator.cell_blocks

    @property
    def dg_rows(self) -> np.ndarray:
        """(n, 30) the ``dg`` coefficient (3·DOF + component) of each owned cell's local stress entries."""
        return self.prolongator.dg_rows

    def release_prolongation(self) -> None:
        """Drop the CSR (and PETSc) P and P_full (made again when asked for); the cell blocks stay."""
        self.prolongator.release()

    @property
    def prolongation_petsc(self) -> PETSc.Mat:
        """P as a distributed PETSc AIJ matrix (global AW numbering; created once)."""
        return self.prolongator.petsc_matrix()

    @property
    def full_prolongation(self) -> sp.csr_matrix:
        """Local P of the unconstrained space: full local AW coefficients -> owned ``dg`` coefficients."""
        return self.prolongator.full

    @property
    def constraint_basis(self) -> sp.csr_matrix:
        """T: reduced local AW coefficients -> full local AW coefficients (identity if unconstrained)."""
        T = self.numbering.T_local
        return sp.identity(self.num_dofs_full, format="csr") if T is None else T

    @staticmethod
    def stress(s: ufl.core.expr.Expr) -> ufl.core.expr.Expr:
        """Symmetric tensor [[s0, s1], [s1, s2]] of a function/argument on ``dg``."""
        return symmetric_tensor(s)

    def to_dg(self, coeffs: npt.ArrayLike, out: dolfinx.fem.Function | None = None) -> dolfinx.fem.Function:
        """Owned AW coefficients c ↦ DG P3 function with coefficients P c (collective)."""
        out = dolfinx.fem.Function(self.dg) if out is None else out
        P = self.prolongation_petsc
        x, y = P.createVecs()
        x.array[:] = np.asarray(coeffs, dtype=np.float64)
        P.mult(x, y)
        out.x.array[: self._n_dg] = y.array
        out.x.scatter_forward()
        x.destroy()
        y.destroy()
        return out

    def interpolate(self, sigma: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
        """AW interpolant: DOF functionals ℓ_i(σ) of a stress field, as owned (reduced) AW coefficients.

        Args:
            sigma: callable x -> components, x of shape (3, N) (dolfinx
                convention, x[2] = 0), returning (3, N) = (σ_xx, σ_xy, σ_yy).
        """
        ent = self.entities
        vx = ent.vx
        d = dof_values(sigma, vx, vx[ent.edge_start], vx[ent.edge_end], vx[ent.c2v])
        T = self.numbering.T_local
        c = d if T is None else T.T @ d
        return c[: self.num_owned]

    def is_stress_space(self, V) -> bool:
        """True if V (python or C++ function space) is ``self.dg``."""
        cpp = getattr(V, "_cpp_object", V)
        return cpp == self.dg._cpp_object

    def assemble_matrix(self, a) -> PETSc.Mat:
        """Assemble a bilinear form; stress arguments are reduced: Pᵀ A P, Pᵀ A or A P (distributed)."""
        form = _as_form(a)
        A = dolfinx.fem.petsc.assemble_matrix(form)
        A.assemble()
        test_s, trial_s = (self.is_stress_space(V) for V in form.function_spaces)
        P = self.prolongation_petsc
        if test_s and trial_s:
            R = A.PtAP(P)
        elif trial_s:
            R = A.matMult(P)
        elif test_s:
            R = P.transposeMatMult(A)
        else:
            return A
        A.destroy()
        return R

    def assemble_vector(self, L) -> np.ndarray:
        """Assemble a linear form to a numpy array of owned entries; on the stress space returns Pᵀ b."""
        form = _as_form(L)
        b = dolfinx.fem.petsc.assemble_vector(form)
        b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        if self.is_stress_space(form.function_spaces[0]):
            P = self.prolongation_petsc
            x = P.createVecRight()
            P.multTranspose(b, x)
            arr = x.array.copy()
            x.destroy()
        else:
            arr = b.getArray(readonly=True).copy()
        b.destroy()
        return arr
