"""The spaces of the mixed subproblem: AW stresses with the essential conditions of the boundary × DG P1.

X_h: lowest-order Arnold–Winther stresses (``fem.arnold_winther``) with σn·t = 0 on Γ_C, σn = t on the
Γ_N groups (a lifting σ_t, so that σ = P c + σ_t) and σn = 0 on the other sides that are not Γ_D or γ;
U_h: discontinuous vector P1.  u = u_D on Γ_D and the Robin condition on γ are natural.
"""

import basix.ufl
import numpy as np
from dolfinx import fem
from dolfinx import mesh as dmesh
from mpi4py import MPI

from fenics_contact.errors import InputError
from fenics_contact.fem.arnold_winther import ArnoldWintherSpace
from fenics_contact.fem.distributed import DistributedMatrix, global_dot
from fenics_contact.fem.linalg import DirectSolver
from fenics_contact.problem.boundary import BoundaryConditions, neumann_groups
from fenics_contact.problem.tags import Boundary

__all__ = [
    "MixedSpaces",
    "boundary_stress_space",
    "check_serial_triangles",
    "check_triangles",
    "displacement_trace_function",
    "interpolate_stress",
]


def check_triangles(msh: dmesh.Mesh) -> None:
    """Raise InputError unless ``msh`` is a mesh of affine triangles (what the AW space supports; any number of
    ranks)."""
    if msh.topology.cell_type != dmesh.CellType.triangle:
        raise InputError(f"the mixed (Arnold–Winther) method needs a triangle mesh, got {msh.topology.cell_type.name}")
    if len(msh.geometry.cmaps) != 1 or msh.geometry.cmaps[0].degree != 1:
        raise InputError("the mixed (Arnold–Winther) method needs an affine (degree 1) triangle mesh")


def check_serial_triangles(msh: dmesh.Mesh) -> None:
    """Raise InputError unless ``msh`` is a serial mesh of affine triangles (for callers that run serially only)."""
    if msh.comm.size > 1:
        raise InputError(
            f"this part of the mixed (Arnold–Winther) method runs in serial only; got {msh.comm.size} MPI ranks. "
            "Run it without mpiexec."
        )
    check_triangles(msh)


def displacement_trace_function(msh: dmesh.Mesh, field) -> fem.Function:
    """u_D interpolated into continuous vector P3 (for the natural term ∫_ΓD u_D·τn ds)."""
    fn = fem.Function(fem.functionspace(msh, basix.ufl.element("Lagrange", msh.basix_cell(), 3, shape=(2,))))
    fn.interpolate(field)
    return fn


def boundary_stress_space(
    msh: dmesh.Mesh,
    facet_tags: dmesh.MeshTags,
    boundary: BoundaryConditions,
    *,
    split_interface=None,
    basis_comm: MPI.Comm | None = None,
    friction: bool = False,
) -> ArnoldWintherSpace:
    """The AW space of a (sub)mesh with the essential stress conditions of its boundary.

    σn·t = 0 on Γ_C (``friction``: none there, the tangential traction is an unknown of the friction law);
    σn = t on the Γ_N groups (a lifting); σn = 0 on every other
    exterior facet that is not Γ_D or γ (traction free).  Γ_D (u = u_D) and γ (Robin)
    are natural.  ``split_interface`` = (γ facets, cells of one side), ``basis_comm`` (ranks holding this same
    serial mesh, which share out its cells' nodal bases): see ``ArnoldWintherSpace``.
    """
    tdim = msh.topology.dim
    msh.topology.create_connectivity(tdim - 1, tdim)
    exterior = dmesh.exterior_facet_indices(msh.topology)
    tagged = np.concatenate([facet_tags.find(t) for t in (Boundary.GAMMA_D, Boundary.GAMMA_C, Boundary.INTERFACE)])
    prescribed = []
    for tag, _, traction in boundary.traction_tags():  # every group on every rank (same list everywhere)
        prescribed.append((facet_tags.find(tag), traction))
    all_neumann = set(neumann_groups(facet_tags))
    neumann = np.concatenate([facet_tags.find(t) for t in sorted(all_neumann)] or [np.zeros(0, np.int32)])
    free = np.setdiff1d(exterior, np.concatenate([tagged, neumann]))
    return ArnoldWintherSpace(
        msh,
        zero_tangential_facets=None if friction else facet_tags.find(Boundary.GAMMA_C),
        zero_traction_facets=np.union1d(free, neumann),
        prescribed_tractions=prescribed,
        split_interface=split_interface,
        basis_comm=basis_comm,
    )


def interpolate_stress(sigma: fem.Function, degree: int = 1, name: str = "sigma") -> fem.Function:
    """(σ_xx, σ_xy, σ_yy) of a DG P3 stress interpolated into DG ``degree`` (0: cell midpoints).

    For output: XDMF writes DG0 (and P1-like) fields, plots take DG0 / DG1.
    """
    msh = sigma.function_space.mesh
    el = basix.ufl.element("DG", msh.basix_cell(), degree, shape=(3,))
    V = fem.functionspace(msh, el)
    out = fem.Function(V, name=name)
    out.interpolate(fem.Expression(sigma, V.element.interpolation_points))
    return out


class MixedSpaces:
    """X_h × U_h of one (sub)mesh, the traction lifting σ_t (σ = P c + σ_t) and P as a distributed matrix.

    ``space``: a prebuilt AW space on ``msh`` (with σ_t = 0 on Γ_C unless ``friction``), else
    ``boundary_stress_space`` (with ``friction``: σn·t free on Γ_C).
    ``distribute_P``: make the distributed P now (the operators need it, or the mesh is distributed: its
    creation is collective); otherwise it is made when first used (0.34 s and 270 MB for Ω₁ at h = 1/128).
    """

    def __init__(
        self,
        msh: dmesh.Mesh,
        facet_tags: dmesh.MeshTags,
        boundary: BoundaryConditions,
        *,
        space: ArnoldWintherSpace | None,
        distribute_P: bool,
        friction: bool = False,
    ) -> None:
        self.space = space or boundary_stress_space(msh, facet_tags, boundary, friction=friction)
        self._Pd: DistributedMatrix | None = None
        if distribute_P:
            self._Pd = DistributedMatrix(self.space.prolongation_petsc)
        self.dg = self.space.dg  #: DG P3 (σ_xx, σ_xy, σ_yy): where the forms are written
        self.U = fem.functionspace(msh, basix.ufl.element("DG", msh.basix_cell(), 1, shape=(2,)))
        self.n_sigma = self.space.num_owned  #: owned AW coefficients
        self.n_u = 2 * self.U.dofmap.index_map.size_local  #: owned DG P1 coefficients
        self.n_dg = 3 * self.dg.dofmap.index_map.size_local  #: owned DG P3 coefficients
        lifting = self.space.lifting_dg
        #: σ_t, the traction lifting, as owned DG P3 coefficients (zero without prescribed tractions)
        self.s0 = np.zeros(self.n_dg) if lifting is None else lifting[: self.n_dg].copy()
        #: whether σ_t is nonzero on any rank (collective)
        self.lifted = bool(msh.comm.allreduce(bool(np.any(self.s0)), op=MPI.LOR))
        self.comm = msh.comm

    @property
    def Pd(self) -> DistributedMatrix:
        """P (owned DG rows × AW DOFs) as a ``DistributedMatrix``."""
        if self._Pd is None:
            self._Pd = DistributedMatrix(self.space.prolongation_petsc)
        return self._Pd

    @property
    def num_dofs(self) -> dict[str, int]:
        """Global stress (AW), displacement and total DOF counts."""
        n_u = self.U.dofmap.index_map.size_global * 2
        return {"sigma": self.space.num_dofs, "u": n_u, "total": self.space.num_dofs + n_u}

    def fit_stress(self, values: np.ndarray, prefix: str) -> tuple[np.ndarray, float]:
        """Owned AW coefficients c with P c + σ_t closest to a DG P3 stress (owned ``dg`` entries) in ℓ².

        Returns c and the relative misfit ‖P c + σ_t − values‖ / ‖values − σ_t‖ (0 when the stress is in
        the space); PᵀP c = Pᵀ(values − σ_t) is solved with MUMPS under the options prefix ``prefix``
        (collective).
        """
        comm = self.comm
        P = self.space.prolongation_petsc
        d = np.asarray(values, dtype=np.float64) - self.s0
        PtP = P.transposeMatMult(P)
        solver = DirectSolver(comm, prefix=prefix)
        try:
            solver.set_operator(PtP)
            rhs, x = PtP.createVecs()
            rhs.array[:] = self.Pd.T @ d
            solver.solve(rhs, x)
            c = x.array.copy()
            for obj in (rhs, x):
                obj.destroy()
        finally:
            solver.destroy()
            PtP.destroy()
        r = self.Pd @ c - d
        misfit = np.sqrt(global_dot(comm, r, r)) / max(np.sqrt(global_dot(comm, d, d)), 1e-300)
        return c, float(misfit)
