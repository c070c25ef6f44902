"""Algorithm 3 for two bodies: each body's bulk a CEM-GMsFEM space, each strip fine, the contact between the strips.

Algorithm 1 for a pair (``hybrid.two_body``) with Ω₁ replaced, body by body, by the multiscale Robin solve of the
one-body Algorithm 3 (``multiscale.cem``): each body's bulk is a serial submesh with γ (its facets against its
strip) and Γ_D (its supports) tagged, its coarse grid the centroid squares of side ``H`` (``problem.strip.
coarse_partition``), its fine operators, relaxed CEM bases with ``cem.layers`` oversampling layers and the
factorized coarse matrix built once; its γ response u₁|γ = R g + r₀ (``MultiscaleRobinSolver.response``) is
exact in the coarse space, so the interface Newton method on the condensed contact unknowns of both strips is
Algorithm 1's.  The two bodies' spaces are independent (no coarse cell holds cells of both).  The fixed point
differs from the monolithic solution by the multiscale error, which falls with the oversampling layers; with
patches covering each bulk and every local mode (``nbasis=None``) the coarse space is the fine one and the fixed
point is Algorithm 1's.  With the pair's friction law the strips are Algorithm 1's frictional strips
(``fem.two_body_friction``): friction lives in Ω₂ only, so the multiscale bulks are unchanged, and ``state``
carries the slip anchors, the displacement and the interface data from one load step to the next.  Tractions
on a bulk's facets enter its load vector (the parent's load over the bulk's cells and their traction facets),
which the source correctors localize as they do the body force.  Under MPI every rank solves the same serial
copy of the pair (``multiscale.pair_replica``: no speed-up, the answer of one process).  A body's supports hold every
component (no rollers), one prescribed displacement per body.

A bulk is refused before either offline phase when it has no cells (the strips take the whole body) or when
its coarse cells are no larger than the fine cells they hold (``check_bulk``: the one-body criterion of
``cli.coarse.check_coarse_cells`` for a partition that is not the mesh's squares).
"""

from dataclasses import dataclass, field

import numpy as np
from dolfinx import fem
from dolfinx import mesh as dmesh

from fenics_contact.errors import InputError
from fenics_contact.fem.contact import NewtonOptions
from fenics_contact.fem.two_body import PairState, load_vector
from fenics_contact.hybrid.two_body import TwoBodyHybridOptions, TwoBodyHybridResult, solve_two_body_hybrid
from fenics_contact.multiscale.cem.cache import offline_stage
from fenics_contact.multiscale.cem.coarse import MultiscaleRobinSolver
from fenics_contact.multiscale.cem.operators import assemble_fine_operators
from fenics_contact.multiscale.cem.options import CEMOptions
from fenics_contact.multiscale.coarse import grid_from_cells
from fenics_contact.multiscale.pair_replica import PairReplica
from fenics_contact.problem.boundary import BoundaryConditions
from fenics_contact.problem.fields import MaterialFields
from fenics_contact.problem.pair import TwoBodyProblem
from fenics_contact.problem.partition import coarse_to_fine as _coarse_to_fine
from fenics_contact.problem.partition import simplex_volumes
from fenics_contact.problem.strip import coarse_partition
from fenics_contact.problem.tags import Boundary

__all__ = ["PairMultiscaleOptions", "bulk_meshes", "check_bulk", "coarse_to_fine", "solve_two_body_ms_hybrid"]


@dataclass(frozen=True, slots=True)
class PairMultiscaleOptions:
    """``H``: the coarse cell size of both bulks (mesh units, > 0); ``cem``: the CEM-GMsFEM parameters."""

    H: float
    cem: CEMOptions = field(default_factory=CEMOptions)

    def __post_init__(self) -> None:
        if isinstance(self.H, bool) or not isinstance(self.H, (int, float, np.number)) or not self.H > 0:
            raise InputError(f"two-body Algorithm 3: H must be a coarse cell size > 0, got {self.H!r}")
        if not isinstance(self.cem, CEMOptions):
            raise InputError(f"two-body Algorithm 3: cem must be a CEMOptions, got {type(self.cem).__name__}")


def _dg0(source: fem.Function, Q0: fem.FunctionSpace, parent_cells: np.ndarray) -> fem.Function:
    """A DG0 field of the parent mesh on a submesh (``parent_cells``: the parent cell of each submesh cell)."""
    out = fem.Function(Q0)
    bs = Q0.dofmap.index_map_bs
    src = source.x.array.reshape(-1, bs)[source.function_space.dofmap.list[parent_cells, 0]]
    out.x.array.reshape(-1, bs)[Q0.dofmap.list[:, 0]] = src
    return out


def _supports_of(problem: TwoBodyProblem, k: int) -> list:
    """The supports on body k (the body of the cell at each support's facets)."""
    msh = problem.mesh
    tdim = msh.topology.dim
    msh.topology.create_connectivity(tdim - 1, tdim)
    f2c = msh.topology.connectivity(tdim - 1, tdim)
    cells = set(problem.body_cells(k).tolist())
    return [s for s in problem.supports if any(f2c.links(f)[0] in cells for f in problem.facet_tags.find(s.facets))]


def coarse_to_fine(grid, cell_nodes: np.ndarray, coords: np.ndarray) -> float:
    """``partition.coarse_to_fine`` of the coarse cells of ``grid`` over the simplices ``cell_nodes`` (vertex
    indices into ``coords``): H/h for squares (cubes) of side H over a mesh of squares (cubes) of side h cut into
    d! simplices."""
    d = cell_nodes.shape[1] - 1
    return _coarse_to_fine(simplex_volumes(coords[cell_nodes][:, :, :d]), grid.cell_coarse, d)


def check_bulk(k: int, n_cells: int, ratio: float | None, H: float, layers: int) -> None:
    """InputError unless body k's bulk (``n_cells`` cells outside the strips of ``layers`` cell layers) has cells
    and coarse cells of side ``H`` larger than its fine cells (``ratio``: ``coarse_to_fine``; None: not yet
    known).  A coarse cell of one fine cell or less has no interior DOFs for its bases: the coarse matrix and the
    interface response are then those of a degenerate space (a wrong answer or non-finite values)."""
    where = f"two-body Algorithm 3 (primal-ms): body {k + 1}"
    if n_cells == 0:
        raise InputError(
            f"{where}: the strips ({layers} cell layers from the contact surfaces) take the whole body, no bulk is "
            "left for its multiscale space; give fewer strip layers ([primal] layers of a case, layers= of a solve) "
            "or a finer mesh"
        )
    if ratio is not None and ratio < 1.0:
        raise InputError(
            f"{where}: the coarse cells of side H = {H:g} are not larger than the {n_cells} fine cells of its bulk "
            f"outside the strips (the median over the coarse cells of |K|^(1/d) over their cells' (d!|T|)^(1/d) is "
            f"{ratio:.3g}): a coarse cell must hold several fine cells; give a finer mesh, fewer strip layers "
            "or a larger H"
        )


def bulk_meshes(problem: TwoBodyProblem, strip: np.ndarray, H: float, layers: int) -> tuple[list, list]:
    """Each body's bulk cells (outside the ``strip`` cells of ``layers`` cell layers) and its serial submesh with
    the coarse grid of side ``H`` (``_bulk_mesh``), each bulk checked by ``check_bulk`` (serial problem)."""
    bulks = [np.setdiff1d(problem.body_cells(k), strip).astype(np.int32) for k in (0, 1)]
    for k, cells in enumerate(bulks):
        check_bulk(k, cells.size, None, H, layers)
    meshes = [_bulk_mesh(problem.mesh, cells, H) for cells in bulks]
    for k, (cells, (sub, *_, grid)) in enumerate(zip(bulks, meshes, strict=True)):
        check_bulk(k, cells.size, coarse_to_fine(grid, sub.geometry.dofmaps[0], sub.geometry.x), H, layers)
    return bulks, meshes


def _bulk_mesh(msh: dmesh.Mesh, cells: np.ndarray, H: float) -> tuple:
    """A bulk's serial submesh (with its cell and vertex maps) and its coarse grid: the centroid squares (cubes) of
    side ``H``, slivers merged (``problem.strip.coarse_partition``)."""
    tdim = msh.topology.dim
    sub, cell_map, vertex_map, _ = dmesh.create_submesh(msh, tdim, cells)
    sub.topology.create_connectivity(tdim - 1, 0)
    sub.topology.create_connectivity(tdim - 1, tdim)
    coarse = coarse_partition(sub, np.ones(cells.size, bool), H)
    return sub, cell_map, vertex_map, grid_from_cells(sub.geometry.dofmaps[0], sub.geometry.x, coarse, H)


class _BodyBulk:
    """One body's bulk: the submesh, its γ / Γ_D tags, the multiscale Robin solver, its DOFs in the parent."""

    def __init__(self, problem: TwoBodyProblem, V, cells, bulk, in_strip, supports, split, options, h) -> None:
        msh = problem.mesh
        tdim, gdim = msh.topology.dim, msh.geometry.dim
        sub, cell_map, vertex_map, grid = bulk
        parent_cells = np.asarray(cell_map.sub_topology_to_topology(np.arange(cells.size, dtype=np.int32), False))
        Vs = fem.functionspace(sub, ("Lagrange", 1, (gdim,)))
        blocks = np.zeros(Vs.dofmap.index_map.size_local, dtype=np.int64)
        blocks[Vs.dofmap.list.ravel()] = V.dofmap.list[parent_cells].ravel()  # P1 DOFs follow the geometry nodes
        self.dofs = (gdim * blocks[:, None] + np.arange(gdim)).ravel()  #: the parent DOF of every submesh DOF
        # the submesh facets: γ (a parent facet between a strip and a bulk cell) and Γ_D (the body's supports)
        msh.topology.create_connectivity(tdim - 1, 0)
        msh.topology.create_connectivity(tdim - 1, tdim)
        f2v, f2c = msh.topology.connectivity(tdim - 1, 0), msh.topology.connectivity(tdim - 1, tdim)
        fmap = msh.topology.index_map(tdim - 1)
        parent = {tuple(sorted(f2v.links(f))): f for f in range(fmap.size_local + fmap.num_ghosts)}
        sub.topology.create_connectivity(tdim - 1, 0)
        sub.topology.create_connectivity(tdim - 1, tdim)
        sf2v = sub.topology.connectivity(tdim - 1, 0)
        n_vertices = sub.topology.index_map(0).size_local
        vertices = np.asarray(vertex_map.sub_topology_to_topology(np.arange(n_vertices, dtype=np.int32), False))
        held = set(np.concatenate([problem.facet_tags.find(s.facets) for s in supports]).tolist())
        entities, values = [], []
        for f in range(sub.topology.index_map(tdim - 1).size_local):
            pf = parent[tuple(sorted(vertices[sf2v.links(f)]))]
            sides = in_strip[f2c.links(pf)]
            tag = (
                Boundary.INTERFACE
                if sides.size == 2 and sides[0] != sides[1]
                else Boundary.GAMMA_D
                if pf in held
                else None
            )
            if tag is not None:
                entities.append(f)
                values.append(int(tag))
        facet_tags = dmesh.meshtags(sub, tdim - 1, np.asarray(entities, np.int32), np.asarray(values, np.int32))
        Q0 = fem.functionspace(sub, ("DG", 0))
        fields = problem.fields
        f_space = fem.functionspace(sub, ("DG", 0, (gdim,)))
        sub_fields = MaterialFields(
            *(_dg0(fn, Q0, parent_cells) for fn in (fields.E, fields.nu, fields.lmbda, fields.mu)),
            _dg0(fields.f, f_space, parent_cells),
            BoundaryConditions(),
        )
        alpha = np.zeros(V.dofmap.index_map.size_local * V.dofmap.index_map_bs)
        alpha[split.gamma] = split.alpha
        alpha_fn = fem.Function(Vs, name="alpha")
        alpha_fn.x.array[:] = alpha[self.dofs]
        moved = [s.displacement for s in supports if s.displacement is not None]
        # with tractions the bulk's load is the parent's over its cells and their traction facets (else its body force)
        load = load_vector(problem, V, cells)[self.dofs] if problem.tractions else None
        ops = assemble_fine_operators(
            Vs,
            facet_tags,
            sub_fields,
            alpha_fn,
            grid,
            s_factor=options.cem.s_factor,
            load=load,
            displacement=(moved or [None])[0],
        )
        space, _ = offline_stage(ops, grid, options.cem, h=h)
        self.solver = MultiscaleRobinSolver(ops, space, grid)
        gamma = self.dofs[ops.gamma]
        #: the solver's γ values that are interface unknowns: a γ DOF on a support (where γ meets Γ_D) carries none
        #: (``split.gamma`` leaves it out; the solver's bases and corrections take no data there)
        self.carried = np.isin(gamma, split.gamma)
        self.gamma = gamma[self.carried]  #: the parent DOFs of the interface unknowns (the solver's order)
        self._data = np.zeros(gamma.size)

    def response(self) -> np.ndarray:
        """∂(u₁ at ``gamma``)/∂(g at ``gamma``): the solver's affine response on the interface unknowns."""
        return self.solver.response()[0][np.ix_(self.carried, self.carried)]

    def solve(self, g: np.ndarray) -> np.ndarray:
        """u₁ on the bulk's DOFs for the Robin data g at ``gamma`` (none at the supported γ DOFs)."""
        self._data[self.carried] = g
        return self.solver.solve(self._data)


class _MultiscaleBulks:
    """Ω₁ of the pair with a CEM-GMsFEM space in each body (``hybrid.two_body``'s Ω₁ interface: ``response``,
    ``solve``, ``destroy``)."""

    def __init__(
        self, problem: TwoBodyProblem, V, split, strip: np.ndarray, options: PairMultiscaleOptions, layers: int
    ) -> None:
        msh = problem.mesh
        tdim, n = msh.topology.dim, V.dofmap.index_map.size_local * V.dofmap.index_map_bs
        n_cells = msh.topology.index_map(tdim).size_local
        in_strip = np.zeros(n_cells, dtype=bool)
        in_strip[strip] = True
        self.weight = np.zeros(n)
        self.weight[split.gamma] = split.weights
        self.position = np.full(n, -1, dtype=np.int64)
        self.position[split.dofs[0]] = np.arange(split.dofs[0].size)
        h = float(np.median(np.abs(msh.h(tdim, np.arange(n_cells, dtype=np.int32)))))
        self.bodies = []
        bulks, meshes = bulk_meshes(problem, strip, options.H, layers)
        for k, (cells, bulk) in enumerate(zip(bulks, meshes, strict=True)):
            supports = _supports_of(problem, k)
            self.bodies.append(_BodyBulk(problem, V, cells, bulk, in_strip, supports, split, options, h))

    def response(self, positions: np.ndarray, weights: np.ndarray) -> np.ndarray:
        """R₁[i, j] = ∂u₁(positions[i])/∂g_j for data weights[j] g_j at positions[j] (block diagonal by body)."""
        at = np.full(self.position.size, -1, dtype=np.int64)
        at[np.flatnonzero(self.position >= 0)[positions]] = np.arange(positions.size)
        R = np.zeros((positions.size, positions.size))
        for bulk in self.bodies:
            index = at[bulk.gamma]
            R[np.ix_(index, index)] = bulk.response()
        return R

    def solve(self, data: np.ndarray) -> np.ndarray:
        """u₁ on the bulk DOFs for the data vector ``data`` (w_p g_p at the γ DOFs)."""
        u = np.zeros(data.size)
        for bulk in self.bodies:
            g = data[self.position[bulk.gamma]] / self.weight[bulk.gamma]
            u[self.position[bulk.dofs]] = bulk.solve(g)
        return u

    def destroy(self) -> None:
        """(Nothing to free: the coarse factorizations are dense.)"""


def solve_two_body_ms_hybrid(
    problem: TwoBodyProblem,
    multiscale: PairMultiscaleOptions,
    *,
    delta: float | None = None,
    options: TwoBodyHybridOptions = TwoBodyHybridOptions(),
    newton: NewtonOptions = NewtonOptions(),
    state: PairState | None = None,
) -> TwoBodyHybridResult:
    """Algorithm 3 for two bodies (module docstring): ``hybrid.two_body.solve_two_body_hybrid`` with each bulk a
    CEM-GMsFEM space; under MPI the same serial pair on every rank (``multiscale.pair_replica``).  ``state``:
    the previous load step's ``.state`` (with friction: the anchors its slip is measured from)."""
    if not isinstance(multiscale, PairMultiscaleOptions):
        raise InputError(f"two-body Algorithm 3 takes PairMultiscaleOptions, got {type(multiscale).__name__}")
    if problem.comm.size > 1:  # the same serial pair on every rank (``multiscale.pair_replica``)
        copy = PairReplica(problem)
        serial = solve_two_body_ms_hybrid(
            copy.problem, multiscale, delta=delta, options=options, newton=newton, state=copy.serial_state(state)
        )
        return copy.distributed(serial)
    for s in problem.supports:
        if s.components is not None:
            raise InputError("two-body Algorithm 3 (primal-ms): a support holds every component (no rollers)")
    for k in (0, 1):
        if sum(s.displacement is not None for s in _supports_of(problem, k)) > 1:
            raise InputError("two-body Algorithm 3 (primal-ms): one prescribed displacement per body")

    def omega1(problem_, V, split, strip):
        return _MultiscaleBulks(problem_, V, split, strip, multiscale, options.layers)

    return solve_two_body_hybrid(problem, delta=delta, options=options, newton=newton, state=state, omega1=omega1)
