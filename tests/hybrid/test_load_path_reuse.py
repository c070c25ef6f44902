"""Algorithm 1's load steps reuse what the obstacle's motion leaves unchanged, with the answers of the plain path.

* ``PrimalPart.body_load`` is assembled again only when the values it is assembled from change
  (``PrimalSubproblem.body_load_inputs``): a moved obstacle keeps it, a new body force or u_D does not, and the
  kept vector equals a fresh assembly bit for bit.
* ``PrimalPart.solve_for`` (Ω₁ as the kept J⁻¹b plus one back-solve of the data, a sparse right-hand side on one
  process) gives Ω₁'s own solve to 1e-12, with and without a body force.
* The relative change's K u₁ taken from the equations Ω₁'s back-solve solved is the product with K to 1e-12.
* On one process the mass products of the relative change by M's block of one component (the scalar mass matrix,
  assembled alone) are PETSc's products, and M is not assembled.
* On one process ``InterfaceSpace``'s transfers are copies of the interface entries: the values of the general
  transfers through the parent space, bit for bit.
* A force–indentation curve through the condensed Newton with these gives the forces of the plain path (the body
  load assembled at every call, Ω₁ by its own solve, four quadratic forms per subdomain for the relative change)
  to 1e-12, the same relative changes to 1e-6, certified steps, and the monolithic forces to 1e-10.
"""

import numpy as np
import pytest
from dolfinx import fem
from mpi4py import MPI

from fenics_contact.fem.matrices import ComponentBlockProduct
from fenics_contact.hybrid.iteration import InterfaceNewtonOptions, IterationOptions
from fenics_contact.hybrid.primal import PrimalHybridStep
from fenics_contact.hybrid.response import PrimalPart
from fenics_contact.indentation import force_indentation
from fenics_contact.problem.geometry import unit_square
from fenics_contact.problem.models import get_model
from fenics_contact.problem.obstacles import Circle

serial = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="the copies are the serial transfers")

CYLINDER = Circle((3.0, 0.5), 2.0)
LEFT = (-1.0, 0.0)
DEPTHS = np.linspace(0.002, 0.02, 4)


def _model():
    return get_model(3, E_high=1e3).with_(obstacle=CYLINDER.indented(DEPTHS[0], LEFT))


def _fresh(assemble, part: PrimalPart) -> np.ndarray:
    """The body load assembled now."""
    return assemble(part.sub.b.duplicate()).getArray(readonly=True).copy()


@pytest.mark.parametrize("which", [0, 1])
def test_body_load_is_kept_while_its_inputs_are(which):
    step = PrimalHybridStep(_model().on(unit_square(16, 4)))
    step.prepare()
    problem = step.interface_problem(InterfaceNewtonOptions())
    part = problem.omega1.part if which == 0 else problem.omega2
    assemblies = []
    assemble = part.sub.body_load
    part.sub.body_load = lambda out: assemblies.append(1) or assemble(out)
    first = part.body_load()
    step.contact.set_obstacle(CYLINDER.indented(DEPTHS[-1], LEFT))  # the obstacle moves: b stays
    again = part.body_load()
    assert len(assemblies) == 1 and np.array_equal(first, again) and np.array_equal(first, _fresh(assemble, part))
    part.sub.fields.f.x.array[:] = 1.0  # a body force: assembled again
    loaded = part.body_load()
    assert len(assemblies) == 2 and not np.array_equal(loaded, first)
    assert np.array_equal(loaded, _fresh(assemble, part))


@pytest.mark.parametrize("force", [0.0, 1.0])
@pytest.mark.parametrize("sparse", [True, False])
def test_solve_for_equals_the_subproblem_solve(force, sparse, monkeypatch):
    """Ω₁ for data g: the kept J⁻¹b plus the sparse right-hand side's back-solve (one process; J⁻¹b by one too), or
    one back-solve of b + C g, equal Ω₁'s own solve, with and without a body force (b = 0: J⁻¹b without a solve)."""
    step = PrimalHybridStep(_model().on(unit_square(16, 4)))
    step.prepare()
    part = step.interface_problem(InterfaceNewtonOptions()).omega1.part
    part.sub.fields.f.x.array[:] = force
    assert part.solver.sequential_mumps() == (MPI.COMM_WORLD.size == 1)
    if not sparse:
        monkeypatch.setattr(type(part.solver), "sequential_mumps", lambda self: False)
    sparse_solves = []
    solve_sparse = type(part.solver).solve_sparse
    monkeypatch.setattr(type(part.solver), "solve_sparse", lambda *a: sparse_solves.append(1) or solve_sparse(*a))
    rng = np.random.default_rng(3)
    g = rng.standard_normal(part.n_g) * step.alpha * 1e-3
    step.interface.to_part(g, 0, part.sub.g)
    part.sub.solve()  # from zero: Ω₁'s own solve
    own = part.sub.u.x.array.copy()
    part.sub.u.x.array[:] = rng.standard_normal(own.size)  # (overwritten)
    part.solve_for(step.interface.gather(g))
    scale = np.abs(own).max()
    assert scale > 0 and np.abs(part.sub.u.x.array - own).max() <= 1e-12 * scale
    # one process: the data's back-solve and, with a body force, J⁻¹b's by sparse right-hand sides
    assert len(sparse_solves) == ((1 + (force != 0)) if sparse and MPI.COMM_WORLD.size == 1 else 0)
    assert (np.abs(part.load_solution()).max() > 0) == (force != 0)
    with pytest.raises(ValueError, match="without contact"):
        step.interface_problem(InterfaceNewtonOptions()).omega2.solve_for(np.zeros(part.n_g))


@pytest.mark.parametrize("force", [0.0, 1.0])
def test_omega1_stiffness_product_from_its_equations(force):
    """The relative change's K u₁ from the equations Ω₁'s back-solve solved (b + C g − R u₁ on the free rows, 0 on
    Γ_D) is the product with K to 1e-12 there; without a ``solve_for`` state it is not taken."""
    step = PrimalHybridStep(_model().on(unit_square(16, 4)))
    step.prepare()
    part = step.interface_problem(InterfaceNewtonOptions()).omega1.part
    part.sub.fields.f.x.array[:] = force
    rng = np.random.default_rng(4)
    g12 = rng.standard_normal(step.interface.size) * step.alpha * 1e-3
    Ku, product = part.sub.u.x.petsc_vec.duplicate(), part.sub.u.x.petsc_vec.duplicate()
    step._solve_omega1(g12, False)  # Ω₁'s own solve: no equations kept
    assert not step._omega1_stiffness_product(Ku)
    step._solve_omega1(g12, True)  # the condensed Newton's: PrimalPart.solve_for
    assert step._omega1_stiffness_product(Ku)
    part.sub.norm_products(part.sub.u, product, Ku.duplicate())
    fixed = step._robin[2]
    assert fixed.any() and not fixed.all()
    ours, theirs = Ku.getArray(), product.getArray()
    scale = MPI.COMM_WORLD.allreduce(np.abs(theirs).max(), op=MPI.MAX)
    assert scale > 0 and np.all(ours[fixed] == 0.0)
    assert MPI.COMM_WORLD.allreduce(np.abs(ours - theirs)[~fixed].max(), op=MPI.MAX) <= 1e-12 * scale
    x = part.sub.u.x.petsc_vec
    assert abs(Ku.dot(x) - product.dot(x)) <= 1e-12 * abs(product.dot(x))  # a(u₁, u₁)
    for vec in (Ku, product):
        vec.destroy()


@serial
def test_mass_products_by_one_component_block():
    """``norm_products``' M w on one process (M's block of one component applied to the components side by side,
    ``ComponentBlockProduct``, from the scalar mass matrix assembled alone: M itself is not assembled) is PETSc's
    product with M, entry for entry, and that block is M's, bit for bit."""
    step = PrimalHybridStep(_model().on(unit_square(16, 4)))
    rng = np.random.default_rng(6)
    for sub in step.sub:
        sub.u.x.array[:] = rng.standard_normal(sub.u.x.array.size)
        ours, theirs = sub.u.x.petsc_vec.duplicate(), sub.u.x.petsc_vec.duplicate()
        sub.norm_products(sub.u, None, ours)
        assert sub._mass_matrix is None  # (the scalar block only)
        sub._M.mult(sub.u.x.petsc_vec, theirs)
        block = ComponentBlockProduct(sub._M, sub.V.dofmap.index_map_bs).block
        for name in ("indptr", "indices", "data"):
            assert np.array_equal(getattr(sub._mass.block, name), getattr(block, name))
        assert np.abs(theirs.getArray()).max() > 0
        assert np.allclose(ours.getArray(), theirs.getArray(), rtol=1e-15, atol=0.0)
        for vec in (ours, theirs):
            vec.destroy()


@serial
def test_serial_transfers_are_the_general_ones():
    step = PrimalHybridStep(_model().on(unit_square(16, 4)))
    iface = step.interface
    assert iface._at is not None
    rng = np.random.default_rng(5)
    values = rng.standard_normal(iface.size)
    for i, space in enumerate(iface.spaces):
        u = fem.Function(space)
        u.x.array[:] = rng.standard_normal(u.x.array.size)
        out = [fem.Function(space) for _ in range(2)]
        copies = iface.from_part(u, i)
        iface.to_part(values, i, out[0])
        at, iface._at = iface._at, None  # the transfers through the parent space
        try:
            assert np.array_equal(copies, iface.from_part(u, i))
            iface.to_part(values, i, out[1])
        finally:
            iface._at = at
        assert np.array_equal(out[0].x.array, out[1].x.array)


def _curve(cm, method="primal"):
    """The curve and the relative change of every step's pair (hybrid)."""
    options = {} if method.endswith("monolithic") else {"options": IterationOptions(accel="newton", tol=1e-10)}
    changes = []
    record = None if method.endswith("monolithic") else lambda _, solver: changes.append(solver.relative_change())
    curve = force_indentation(_model().on(cm), method, DEPTHS, direction=LEFT, on_step=record, **options)
    return curve, np.array(changes)


def test_load_path_equals_the_plain_path(monkeypatch):
    cm = unit_square(32, 8)
    solves = []
    solve_for = PrimalPart.solve_for
    monkeypatch.setattr(PrimalPart, "solve_for", lambda self, g: solves.append(1) or solve_for(self, g))
    fast, fast_changes = _curve(cm)
    assert len(solves) == DEPTHS.size  # Ω₁ from the kept body load at every step
    omega1 = fast.step.sub[0]
    assert omega1._stiffness is None  # Ω₁'s K u₁ from its equations: its K never assembled
    assert omega1._mass_matrix is None  # its mass products by the scalar block
    assert not any(isinstance(omega1._forms[name], fem.Form) for name in ("a", "m", "load"))  # never compiled
    mono, _ = _curve(cm, "primal-monolithic")

    def assembled(self):  # the body load assembled at every call
        return self.sub.body_load(self._b).getArray(readonly=True).copy()

    monkeypatch.setattr(PrimalPart, "body_load", assembled)
    monkeypatch.setattr(PrimalHybridStep, "_solve_omega1", lambda self, g12, condensed: self.sub[0].solve())
    measure = PrimalHybridStep._measure
    monkeypatch.setattr(PrimalHybridStep, "_measure", lambda self, kept=False: measure(self))
    plain, plain_changes = _curve(cm)
    assert all(s.converged and s.iterations == 1 for s in fast.steps + plain.steps)
    assert np.max(np.abs(fast.forces - plain.forces) / np.abs(plain.forces)) <= 1e-12
    assert np.max(np.abs(fast.forces - mono.forces) / np.abs(mono.forces)) <= 1e-10
    assert fast_changes.size == DEPTHS.size and np.allclose(fast_changes, plain_changes, rtol=1e-6, atol=0.0)
    assert np.all(fast.transmission_residuals < 1e-10)
