"""The AMG-preconditioned Krylov solver of the primal Newton (``fem.amg.AMGSolver``) against MUMPS."""

import basix.ufl
import dolfinx.fem.petsc
import dolfinx.mesh
import numpy as np
import pytest
import ufl
from dolfinx import fem
from mpi4py import MPI
from petsc4py import PETSc

from fenics_contact.errors import ConvergenceError, InputError
from fenics_contact.fem import forms_primal
from fenics_contact.fem.amg import AUTO_AMG_DOFS, AMGSolver, LinearSolverOptions, linear_solver, rigid_body_modes
from fenics_contact.fem.linalg import DirectSolver
from fenics_contact.fem.primal import solve_primal_monolithic
from fenics_contact.methods import METHODS
from fenics_contact.problem.boundary import BoundaryConditions
from fenics_contact.problem.geometry import unit_square
from fenics_contact.problem.meshes3d import unit_cube
from fenics_contact.problem.models import get_model
from fenics_contact.problem.models3d import channels_3d, channels_3d_mesh
from fenics_contact.problem.obstacles import Sphere
from fenics_contact.problem.problem import ContactProblem

#: the Krylov tolerance of the comparisons: ‖b − A x‖ ≤ RTOL‖b‖ in every Newton step
RTOL = 1e-10
#: CG iterations allowed per Newton step (measured: 2D 49–58, 3D 16–34 with the heterogeneous AMG these contrasts get)
MAX_ITERATIONS = 80


def _model_1_2d():
    """Test model 1 (eight stiff channels, E 1e3 : 1) on h = 1/32, pushed onto the wall at x = 1."""
    return get_model(1, E_high=1e3).on(unit_square(32, 8))


def _layered_cube(comm: MPI.Comm = MPI.COMM_WORLD):
    """The unit cube (h = 1/8) clamped at x = 0, a stiff slab 1/4 < x < 1/2 and a stiff bar 1/2 < x < 7/8,
    y < 1/2 under the contact (E = 1e3 beside E = 1), a sphere pressed into its face x = 1 off-centre."""
    ball = Sphere((1.5, 0.45, 0.55), 0.5).indented(0.06, (-1.0, 0.0, 0.0))

    def modulus(x):
        stiff = ((x[0] > 0.25) & (x[0] < 0.5)) | ((x[0] > 0.5) & (x[0] < 0.875) & (x[1] < 0.5) & (x[2] > 0.25))
        return np.where(stiff, 1e3, 1.0)

    return ContactProblem(
        youngs_modulus=modulus,
        poisson_ratio=0.3,
        obstacle=ball,
        mesh=unit_cube(8, comm=comm),
        boundary=BoundaryConditions(),
    )


@pytest.mark.parametrize("build", [_model_1_2d, _layered_cube], ids=["2d-channels", "3d-slab"])
def test_amg_and_mumps_find_the_same_contact(build):
    """The same semismooth Newton with CG + AMG and with MUMPS: the same active sets step by step, the contact
    force and the displacement equal to the Krylov tolerance, the CG iterations per step bounded."""
    problem = build()
    direct = solve_primal_monolithic(problem, solver="direct")
    amg = solve_primal_monolithic(problem, solver=LinearSolverOptions(kind="amg", rtol=RTOL))
    assert direct.linear_solver == "direct" and direct.krylov_iterations == []
    assert amg.linear_solver == "amg" and len(amg.krylov_iterations) == amg.newton.steps
    assert amg.newton.active_sizes == direct.newton.active_sizes and amg.newton.active_sizes[-1] > 0
    assert np.array_equal(amg.profile.active, direct.profile.active)
    assert amg.profile.force == pytest.approx(direct.profile.force, rel=1e3 * RTOL)
    comm = problem.comm
    diff = comm.allreduce(float(np.max(np.abs(amg.u.x.array - direct.u.x.array), initial=0.0)), op=MPI.MAX)
    size = comm.allreduce(float(np.max(np.abs(direct.u.x.array), initial=0.0)), op=MPI.MAX)
    assert diff <= 1e3 * RTOL * size
    assert max(amg.krylov_iterations) <= MAX_ITERATIONS
    assert amg.problem.solver.factorizations == direct.problem.solver.factorizations  # one set-up per active set


def test_gmres_with_amg_is_the_same_solve():
    """GMRES (for an unsymmetric Jacobian; right-preconditioned, the true residual) on the symmetric one: the
    solve of CG and of MUMPS."""
    problem = _layered_cube()
    direct = solve_primal_monolithic(problem, solver="direct")
    gmres = solve_primal_monolithic(problem, solver=LinearSolverOptions(kind="amg", krylov="gmres", rtol=RTOL))
    assert gmres.newton.active_sizes == direct.newton.active_sizes
    assert gmres.profile.force == pytest.approx(direct.profile.force, rel=1e3 * RTOL)
    assert gmres.problem.solver.ksp.getType() == "gmres" and max(gmres.krylov_iterations) <= MAX_ITERATIONS


@pytest.mark.parametrize("n, dim", [(4, 2), (3, 3)])
def test_rigid_body_modes_span_the_kernel_of_the_free_stiffness(n, dim):
    """3 modes in 2D, 6 in 3D, orthonormal, and K m = 0 for the stiffness K of the unconstrained body."""
    cm = unit_square(n, 2) if dim == 2 else unit_cube(n)
    msh = cm.mesh
    V = fem.functionspace(msh, basix.ufl.element("Lagrange", msh.basix_cell(), 1, shape=(dim,)))
    modes = rigid_body_modes(V)
    assert len(modes) == 3 * (dim - 1)
    gram = np.array([[u.dot(v) for v in modes] for u in modes])
    assert np.allclose(gram, np.eye(len(modes)), atol=1e-12)
    K = dolfinx.fem.petsc.assemble_matrix(
        fem.form(forms_primal.elastic_form(ufl.TrialFunction(V), ufl.TestFunction(V), 1.0, 1.0))
    )
    K.assemble()
    out = modes[0].duplicate()
    for m in modes:
        K.mult(m, out)
        assert out.norm() <= 1e-12 * K.norm()
    for obj in (K, out, *modes):
        obj.destroy()


def test_a_krylov_failure_says_what_to_do():
    problem = _model_1_2d()
    with pytest.raises(ConvergenceError, match="did not converge.*DIVERGED_MAX_IT.*solver='direct'"):
        solve_primal_monolithic(problem, solver=LinearSolverOptions(kind="amg", max_iterations=2))


def test_linear_solver_options_are_checked_and_auto_chooses_by_size_and_dimension():
    for bad in (dict(kind="lu"), dict(krylov="bicg"), dict(rtol=0.0), dict(max_iterations=0), dict(auto_dofs=True)):
        with pytest.raises(InputError):
            LinearSolverOptions(**bad)
    with pytest.raises(InputError, match="solver must be one of"):
        LinearSolverOptions.of(3)
    auto = LinearSolverOptions()
    assert auto.kind == "auto" and LinearSolverOptions.of("amg").kind == "amg"
    assert auto.chosen(AUTO_AMG_DOFS, 3) == "amg" and auto.chosen(AUTO_AMG_DOFS - 1, 3) == "direct"
    assert auto.chosen(10 * AUTO_AMG_DOFS, 2) == "direct" and LinearSolverOptions(kind="amg").chosen(10, 2) == "amg"
    msh = unit_cube(2).mesh
    V = fem.functionspace(msh, basix.ufl.element("Lagrange", msh.basix_cell(), 1, shape=(3,)))
    small = linear_solver(msh.comm, prefix="test_auto_small_", space=V, options="auto")
    forced = linear_solver(msh.comm, prefix="test_auto_amg_", space=V, options=LinearSolverOptions(auto_dofs=3))
    assert isinstance(small, DirectSolver) and isinstance(forced, AMGSolver) and not forced.has_inverse_entries()
    M = dolfinx.fem.petsc.assemble_matrix(fem.form(forms_primal.mass_form(ufl.TrialFunction(V), ufl.TestFunction(V))))
    M.assemble()
    forced.set_operator(M)  # (an SPD operator: the AMG is set up, its options used)
    for obj in (small, forced, M):
        obj.destroy()
    assert METHODS["primal-monolithic"].defaults()["solver"] == "auto"
    with pytest.raises(InputError, match="linear solver must be one of"):
        METHODS["primal-monolithic"].solve(_layered_cube(), solver="cholesky")


@pytest.mark.mpi
def test_amg_on_two_ranks_is_the_serial_direct_solve():
    """The heterogeneous cube by CG + AMG distributed over the ranks against MUMPS on one rank: the same contact
    nodes and force to the Krylov tolerance, the iterations bounded."""
    amg = solve_primal_monolithic(_layered_cube(MPI.COMM_WORLD), solver=LinearSolverOptions(kind="amg", rtol=RTOL))
    serial = solve_primal_monolithic(_layered_cube(MPI.COMM_SELF), solver="direct")
    assert amg.newton.active_sizes == serial.newton.active_sizes
    assert amg.profile.force == pytest.approx(serial.profile.force, rel=1e3 * RTOL)
    assert max(amg.krylov_iterations) <= MAX_ITERATIONS


def test_mat_solve_of_a_dense_block_is_the_direct_one():
    """``AMGSolver.mat_solve`` (one checked CG solve per column, as the interface responses call it) against
    MUMPS on the clamped stiffness of a small cube, its Dirichlet rows exact."""
    msh = unit_cube(4).mesh
    V = fem.functionspace(msh, basix.ufl.element("Lagrange", msh.basix_cell(), 1, shape=(3,)))
    msh.topology.create_connectivity(2, 3)
    facets = dolfinx.mesh.locate_entities_boundary(msh, 2, lambda x: np.isclose(x[0], 0.0))
    bc = fem.dirichletbc(np.zeros(3), fem.locate_dofs_topological(V, 2, facets), V)
    form = fem.form(forms_primal.elastic_form(ufl.TrialFunction(V), ufl.TestFunction(V), 1.0, 1.0))
    K = dolfinx.fem.petsc.assemble_matrix(form, bcs=[bc])
    K.assemble()
    n, k = K.getLocalSize()[0], 3
    rng = np.random.default_rng(0)
    B = PETSc.Mat().createDense(
        ((n, PETSc.DECIDE), (PETSc.DECIDE, k)), array=rng.standard_normal((n, k)), comm=msh.comm
    )
    B.assemble()
    solutions = []
    for solver in (
        DirectSolver(msh.comm, prefix="test_block_direct_"),
        AMGSolver(msh.comm, prefix="test_block_amg_", space=V, options=LinearSolverOptions(kind="amg", rtol=RTOL)),
    ):
        X = PETSc.Mat().createDense(((n, PETSc.DECIDE), (PETSc.DECIDE, k)), comm=msh.comm)
        X.setUp()
        X.assemble()
        solver.set_operator(K)
        solver.mat_solve(B, X)
        solutions.append(X.getDenseArray().copy())
        for obj in (solver, X):
            obj.destroy()
    assert np.allclose(solutions[1], solutions[0], rtol=0.0, atol=1e4 * RTOL * np.abs(solutions[0]).max())
    dofs, owned = bc.dof_indices()
    assert np.array_equal(solutions[1][dofs[:owned]], solutions[0][dofs[:owned]])
    for obj in (K, B):
        obj.destroy()


def test_a_linear_subproblem_sets_amg_up_once_for_all_its_solves():
    """A subproblem without contact (the fine Ω₁ of Algorithm 1 is one, with Robin data) keeps one AMG set-up
    for every solve, as it keeps one factorization; its solution is MUMPS' to the Krylov tolerance."""
    from fenics_contact.fem.primal import PrimalSubproblem

    problem = _model_1_2d()
    cm, fields = problem.cm, problem.fields
    solutions = {}
    for kind in ("direct", "amg"):
        options = LinearSolverOptions(kind=kind, rtol=RTOL)
        sub = PrimalSubproblem(
            cm.mesh, cm.facet_tags, fields, delta=None, alpha=None, prefix=f"t_{kind}_", solver=options
        )
        for _ in range(3):
            sub.solve()
        assert sub.solver.factorizations == 1
        solutions[kind] = sub.u.x.array.copy()
        sub.destroy()
    size = np.max(np.abs(solutions["direct"]))
    assert size > 0 and np.max(np.abs(solutions["amg"] - solutions["direct"])) <= 1e3 * RTOL * size


@pytest.mark.parametrize("n", [8, 12])
def test_amg_newton_at_contrast_1e6_takes_the_steps_of_mumps(n):
    """The 3D channel cube at contrast 10⁶ with the default Krylov tolerance: the step that moves the active set leaves
    F full of penalty forces 10⁹× the load, and a solve stopped at rtol‖F‖ leaves the next iterate wrong by more than
    its penetrations (at h = 1/12 the active sets then cycle); stopped at rtol times the next iterate's right-hand
    side (``AMGSolver.newton_tolerance``), with the AMG of heterogeneous operators (``HETEROGENEOUS_OPTIONS``: at
    h = 1/8 smoothed aggregation with Chebyshev smoothing made an indefinite preconditioner), CG + AMG takes the
    active sets of MUMPS step by step and lands on its answer, in a bounded number of CG iterations per step."""
    problem = channels_3d(E_high=1e6).on(channels_3d_mesh(n))
    direct = solve_primal_monolithic(problem, solver="direct")
    amg = solve_primal_monolithic(problem, solver="amg")
    assert amg.linear_solver == "amg" and len(amg.krylov_iterations) == amg.newton.steps
    assert amg.newton.active_sizes == direct.newton.active_sizes
    np.testing.assert_array_equal(amg.profile.active, direct.profile.active)
    gap = np.linalg.norm(amg.u.x.array - direct.u.x.array)
    assert gap <= 1e-7 * np.linalg.norm(direct.u.x.array)
    assert max(amg.krylov_iterations) <= MAX_ITERATIONS
