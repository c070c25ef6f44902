"""Fine-scale operators of Ω₁ for the primal CEM (Algorithm 3): the forms, ``FineOperators``, the Ω₁ load.

Every matrix lives on a serial (COMM_SELF) copy of Ω₁.  The cellwise matrices a_i, s_i and the γ-mass of a
coarse cell K_i come from a colouring of the coarse cells (``CoarseGrid.colors``): cells of one colour share
no fine vertex, so the restriction of the colour-c matrix to the vertices of K_i is the matrix of K_i.
Patch problems need no extra assembly: the rows of the global Ω₁ matrix at the interior DOFs of a patch only
see cells of that patch.  Any load that is an assembled functional on Ω₁ is localized by the source
correction (``omega1_load``: body force and Γ_N tractions), a prescribed displacement through its lifting
(``assemble_fine_operators(displacement=)``; the package docstring has the formulas).
"""

from dataclasses import dataclass, field

import dolfinx.mesh
import numpy as np
import scipy.sparse as sp
import ufl
from dolfinx import fem, la
from mpi4py import MPI

from fenics_contact.errors import InputError
from fenics_contact.fem import forms_primal
from fenics_contact.fem.matrices import assemble_scipy
from fenics_contact.multiscale.coarse import CoarseGrid
from fenics_contact.problem.fields import MaterialFields
from fenics_contact.problem.tags import Boundary

__all__ = [
    "FineOperators",
    "assemble_fine_operators",
    "cem_mass_form",
    "interface_mass_form",
    "kappa_tilde",
    "omega1_load",
    "require_serial",
    "roller_dofs",
]


def require_serial(comm: MPI.Comm) -> None:
    """Raise InputError on a communicator with more than one rank (for code that needs the serial Ω₁ copy)."""
    if comm.size > 1:
        raise InputError(
            f"this CEM operation needs a serial (COMM_SELF) mesh; got a communicator with {comm.size} ranks"
        )


def kappa_tilde(lmbda, mu, H, factor: float = 1.0):
    """κ̃ = factor · (λ + 2μ) H⁻² (H a number or a cellwise function)."""
    return factor * (lmbda + 2.0 * mu) / H**2


def cem_mass_form(u, v, weight):
    """s(u, v) = ∫ weight u·v dx (weight = χ κ̃ with χ a coarse-cell indicator)."""
    return weight * ufl.inner(u, v) * ufl.dx


def interface_mass_form(u, v, weight, ds_gamma):
    """∫_γ weight u·v ds (vertex quadrature through ``ds_gamma``)."""
    return weight * ufl.inner(u, v) * ds_gamma


@dataclass(slots=True)
class FineOperators:
    """SciPy matrices of the Ω₁ P1 space (no boundary conditions applied; ``free`` marks non-Γ_D DOFs).

    K: a(u, v); R: α∫_γ u·v; A = K + R; M: (u, v); G: ∫_γ u·v (vertex quadrature); F: the load ℓ(v);
    ``free`` is false on Γ_D and on the components held by roller planes (u_i = 0 on x_i = c);
    Kc/Mc/Sc/Gc: a, the mass, s and the γ-mass restricted to the cells of one colour (index = colour).
    """

    V: fem.FunctionSpace
    K: sp.csr_matrix
    R: sp.csr_matrix
    A: sp.csr_matrix
    M: sp.csr_matrix
    G: sp.csr_matrix
    Kc: list
    Mc: list
    Sc: list
    Gc: list
    F: np.ndarray
    free: np.ndarray  #: bool, scalar DOF not on Γ_D nor held by a roller plane
    gamma: np.ndarray  #: scalar DOFs on γ (sorted), the columns of N
    alpha: np.ndarray  #: nodal α at every scalar DOF (zero off γ)
    node_dofs: np.ndarray  #: (num nodes, bs) scalar DOFs of each node
    cell_nodes: np.ndarray  #: (num cells, 3) nodes of each cell
    key_data: dict = field(default_factory=dict)  #: arrays the offline data depend on (for the cache key)
    #: the lifting u_g of a prescribed displacement (u_D at the Γ_D DOFs, zero elsewhere), or None
    lifting: np.ndarray | None = None
    #: the load the source correctors localize: F − A u_g with a lifting, else F (``corrector_load``)
    F_lifted: np.ndarray | None = None

    @property
    def corrector_load(self) -> np.ndarray:
        """ℓ(v) − a₁(u_g, v) − α∫_γ u_g·v: the load of the homogeneous part u₁ − u_g (F without a lifting)."""
        return self.F if self.F_lifted is None else self.F_lifted

    @property
    def size(self) -> int:
        """Number of scalar DOFs of the Ω₁ space (Γ_D included)."""
        return self.K.shape[0]

    @property
    def bs(self) -> int:
        return self.node_dofs.shape[1]


def roller_dofs(V: fem.FunctionSpace, facet_tags, rollers) -> np.ndarray:
    """The scalar DOFs u_i held by the roller planes x_i = c of ``rollers`` ((i, c) pairs) on a serial mesh: the
    component i at the vertices of the exterior facets in the plane (γ excepted; a plane with no facet of this
    mesh holds none: it lies on another part of the body)."""
    msh = V.mesh
    require_serial(msh.comm)
    if not rollers:
        return np.zeros(0, dtype=np.int64)
    tdim, gdim = msh.topology.dim, msh.geometry.dim
    bs = V.dofmap.index_map_bs
    x = msh.geometry.x[:, :gdim]
    tol = 1e-10 * float(np.max(np.ptp(x, axis=0)))
    gamma = facet_tags.find(Boundary.INTERFACE)
    held = []
    for axis, value in rollers:
        if axis >= gdim:
            raise InputError(f"a roller plane x_{axis} = {value:g} needs a {axis + 1}D mesh; this one is {gdim}D")

        def in_plane(p: np.ndarray, a: int = axis, c: float = value) -> np.ndarray:
            return np.abs(p[a] - c) <= tol

        facets = dolfinx.mesh.locate_entities_boundary(msh, tdim - 1, in_plane)
        facets = np.setdiff1d(facets, gamma)
        blocks = fem.locate_dofs_topological(V, tdim - 1, facets)
        held.append(bs * np.asarray(blocks, dtype=np.int64) + axis)
    return np.unique(np.concatenate(held))


def _over(form: ufl.Form, measure: ufl.Measure) -> ufl.Form:
    """The one cell integral of ``form`` (written with ``ufl.dx``) over ``measure`` instead."""
    (integral,) = form.integrals()
    return integral.integrand() * measure


def assemble_fine_operators(
    V: fem.FunctionSpace,
    facet_tags,
    fields: MaterialFields,
    alpha: fem.Function,
    grid: CoarseGrid,
    *,
    s_factor: float = 1.0,
    load: np.ndarray | None = None,
    displacement=None,
) -> FineOperators:
    """Assemble every Ω₁ matrix the CEM construction needs (serial mesh; colour-restricted copies included).

    ``load`` (optional) replaces the body-force vector (f, v) as the Ω₁ load ℓ(v): any assembled
    functional (tractions).  ``displacement`` (optional): a prescribed u_D on Γ_D (a callable
    x(3, N) -> (2, N) or a constant 2-vector, as ``BoundaryConditions.displacement``); its lifting
    u_g (u_D at the Γ_D DOFs, zero elsewhere) is ``FineOperators.lifting`` and the source correctors
    localize ℓ − A u_g (``corrector_load``).
    """
    msh = V.mesh
    require_serial(msh.comm)
    tdim = msh.topology.dim
    bs = V.dofmap.index_map_bs
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    ds = forms_primal.vertex_measure(msh, facet_tags)(Boundary.INTERFACE)
    Q0 = fields.E.function_space
    cell_dof0 = Q0.dofmap.list[:, 0]
    size = fem.Function(Q0, name="H_K")
    size.x.array[cell_dof0] = grid.cell_size[grid.cell_coarse]
    kap = kappa_tilde(fields.lmbda, fields.mu, size, s_factor)
    a = alpha.x.array.copy()
    fine_colour = grid.colors[grid.cell_coarse]
    Kc, Mc, Sc, Gc = [], [], [], []
    num_cells = msh.topology.index_map(tdim).size_local
    cells = np.arange(num_cells, dtype=np.int32)
    for c in range(grid.num_colors):
        # the cell integrals over the cells of colour c only (tagged 0 here: one compiled form for all colours);
        # the γ facet integral keeps the indicator χ (γ's few facets cost nothing)
        in_c = dolfinx.mesh.meshtags(msh, tdim, cells, (fine_colour[:num_cells] != c).astype(np.int32))
        dx_c = ufl.Measure("dx", domain=msh, subdomain_data=in_c)(0)
        chi = fem.Function(Q0, name=f"chi{c}")
        chi.x.array[cell_dof0] = (fine_colour == c).astype(np.float64)
        Kc.append(assemble_scipy(_over(forms_primal.elastic_form(u, v, fields.lmbda, fields.mu), dx_c)))
        Mc.append(assemble_scipy(ufl.inner(u, v) * dx_c))
        Gc.append(assemble_scipy(interface_mass_form(u, v, chi, ds)))
        Sc.append(assemble_scipy(_over(cem_mass_form(u, v, kap), dx_c)))
    K = sum(Kc[1:], Kc[0]).tocsr()
    M = sum(Mc[1:], Mc[0]).tocsr()
    G = sum(Gc[1:], Gc[0]).tocsr()
    R = (sp.diags(a) @ G).tocsr()
    A = (K + R).tocsr()
    if load is None:
        F_vec = fem.assemble_vector(fem.form(ufl.inner(fields.f, v) * ufl.dx))
        F_vec.scatter_reverse(la.InsertMode.add)
        F = F_vec.array.copy()
    else:
        F = np.asarray(load, dtype=np.float64).copy()
        if F.shape != (K.shape[0],):
            raise InputError(f"the Ω₁ load vector has shape {F.shape}, expected ({K.shape[0]},)")
    n = K.shape[0]
    msh.topology.create_connectivity(tdim - 1, tdim)
    dir_blocks = fem.locate_dofs_topological(V, tdim - 1, facet_tags.find(Boundary.GAMMA_D))
    gam_blocks = fem.locate_dofs_topological(V, tdim - 1, facet_tags.find(Boundary.INTERFACE))
    free = np.ones(n, dtype=bool)
    dirichlet = (bs * dir_blocks[:, None] + np.arange(bs)).ravel()
    free[dirichlet] = False
    free[roller_dofs(V, facet_tags, fields.boundary.rollers)] = False
    gamma = np.sort((bs * gam_blocks[:, None] + np.arange(bs)).ravel())
    num_nodes = n // bs
    node_dofs = bs * np.arange(num_nodes)[:, None] + np.arange(bs)
    cell_nodes = V.dofmap.list.copy()
    lam = fields.lmbda.x.array[cell_dof0]
    mu = fields.mu.x.array[cell_dof0]
    key_data = {
        "E": fields.E.x.array[cell_dof0],
        "nu": fields.nu.x.array[cell_dof0],
        "lame": np.concatenate([lam, mu]),
        "alpha": a,
        "coords": V.tabulate_dof_coordinates(),
        "cell_nodes": cell_nodes,
        "cell_coarse": grid.global_index[grid.cell_coarse],
        "cell_size": grid.cell_size,
        "free": free,
        "load": F,
    }
    lifting = F_lifted = None
    if displacement is not None and dir_blocks.size:
        u_D = fem.Function(V)
        u_D.interpolate(
            displacement
            if callable(displacement)
            else (lambda x, c=np.asarray(displacement, dtype=np.float64): np.tile(c[:, None], (1, x.shape[1])))
        )
        lifting = np.zeros(n)
        lifting[dirichlet] = u_D.x.array[dirichlet]
        if np.any(lifting):
            F_lifted = F - A @ lifting
            key_data["lifting"] = lifting
        else:
            lifting = None
    return FineOperators(
        V, K, R, A, M, G, Kc, Mc, Sc, Gc, F, free, gamma, a, node_dofs, cell_nodes, key_data, lifting, F_lifted
    )


def omega1_load(V: fem.FunctionSpace, facet_tags, fields: MaterialFields) -> np.ndarray | None:
    """The Ω₁ load vector ℓ(v) = (f, v) + Σ_k ∫_ΓN,k t_k·v ds on a serial Ω₁ mesh, or None without tractions.

    The tractions of ``fields.boundary`` whose Γ_N groups have facets in ``facet_tags`` enter
    as in the fine methods (``fem.primal``: t_k interpolated in P1, the boundary integral
    assembled); the source correction then treats them as it treats f (module docstring).
    """
    require_serial(V.mesh.comm)
    present = set(np.unique(facet_tags.values).tolist())
    tractions = [(tag, field_) for tag, _, field_ in fields.boundary.traction_tags() if tag in present]
    if not tractions:
        return None
    v = ufl.TestFunction(V)
    ds = ufl.Measure("ds", domain=V.mesh, subdomain_data=facet_tags)
    pairs = []
    for tag, field_ in tractions:
        t = fem.Function(V)
        t.interpolate(field_)
        pairs.append((t, ds(tag)))
    form = ufl.inner(fields.f, v) * ufl.dx + forms_primal.traction_form(pairs, v)
    vec = fem.assemble_vector(fem.form(form))
    vec.scatter_reverse(la.InsertMode.add)
    return vec.array.copy()
