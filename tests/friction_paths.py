"""Frictional load paths with the displacement on the whole mesh after each step (for comparing methods)."""

from dolfinx import fem

from fenics_contact.sliding import slide


def snapshots(method, problem, path, **options):
    """``slide(problem, method, path)`` and, per step, the displacement on the whole mesh (a hybrid method's parts
    glued)."""
    msh = problem.cm.mesh
    V = fem.functionspace(msh, ("Lagrange", 1, (msh.geometry.dim,)))
    fields = []

    def keep(step, solver):
        u = solver.glued(V) if hasattr(solver, "glued") else solver.contact.u
        fields.append(u.x.array.copy())

    return slide(problem, method, path, on_step=keep, **options), fields
