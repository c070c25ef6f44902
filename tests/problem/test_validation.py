"""A user's mesh is checked against the contact problem before any solve (one test per contradiction)."""

import numpy as np
import pytest
from mpi4py import MPI
from user_meshes import GOOD, build_columns
from user_meshes import solid_or_quads as _solid_or_quads

from fenics_contact.errors import InputError, MeshTagError
from fenics_contact.problem.geometry import read_mesh, unit_square
from fenics_contact.problem.validation import (
    BOUNDARY_RULES,
    BoundaryRule,
    MeshDescription,
    describe_contact_mesh,
    mesh_problems,
    validate_contact_mesh,
)

pytestmark = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="writes mesh files serially; MPI in test_outputs")


def test_a_consistent_user_mesh_is_accepted(tmp_path):
    cm = read_mesh(build_columns(tmp_path / "good.msh"), H=0.25)
    assert np.isclose(cm.h, 1 / 8, rtol=1e-9)  # √(2·largest area): the legs of the 1/8 × (1/8 or 1/4)... cells
    validate_contact_mesh(unit_square(8, 4))  # the built-in mesh obeys the rules


@pytest.mark.parametrize(
    "case, kwargs, messages",
    [
        (
            "gamma on the outer boundary",
            dict(gamma=("v0",), gamma_d=("b0", "b1", "b2", "t0", "t1", "t2")),
            ["segments of 'gamma' lie on the outer boundary", "edges between Omega1 and Omega2 are not tagged 'gamma'"],
        ),
        ("gamma on a Gamma_D curve", dict(gamma=("v0",)), ["'Gamma_D' and 'gamma' share 8 segments"]),
        ("gamma inside Omega1", dict(gamma=("v1",)), ["segments of 'gamma' lie inside Omega1", "not tagged 'gamma'"]),
        (
            "gamma only part of the interface",
            dict(gamma=("v2",), omega1=("A",), omega2=("B", "C")),
            ["segments of 'gamma' lie inside Omega2", "not tagged 'gamma'"],
        ),
        (
            "non-conforming gamma, duplicate nodes",
            dict(interface="duplicate"),
            ["lie inside the domain", "not conforming", "'gamma' lie on the outer boundary", "share no edge"],
        ),
        (
            "non-conforming gamma, hanging nodes",
            dict(interface="hanging"),
            ["lie inside the domain", "'gamma' lie on the outer boundary"],
        ),
        (
            "Gamma_C on Omega1",
            dict(gamma_c=("v0",), gamma_d=("b0", "b1", "b2", "t0", "t1", "t2", "v3")),
            ["segments of 'Gamma_C' are not on the boundary of Omega2"],
        ),
        (
            "Gamma_C inside the domain",
            dict(gamma_c=("v1",)),
            ["segments of 'Gamma_C' are not on the outer boundary", "not on the boundary of Omega2"],
        ),
        (
            "Gamma_D and Gamma_C overlap",
            dict(gamma_d=(*GOOD["gamma_d"], "v3")),
            ["'Gamma_C' and 'Gamma_D' share 8 segments: they must be disjoint"],
        ),
        (
            "Gamma_C touches gamma",
            dict(gamma_c=("v3", "t2"), gamma_d=("v0", "b0", "b1", "b2", "t0", "t1")),
            ["'Gamma_C' touches 'gamma' at 1 nodes"],
        ),
        (
            "Gamma_D inside the domain",
            dict(gamma_d=(*GOOD["gamma_d"], "v1")),
            ["segments of 'Gamma_D' are not on the outer boundary"],
        ),
    ],
)
def test_tag_contradictions_are_refused(tmp_path, case, kwargs, messages):
    path = build_columns(tmp_path / "bad.msh", **kwargs)
    with pytest.raises(MeshTagError) as info:
        read_mesh(path)
    text = str(info.value)
    assert str(path) in text
    for message in messages:
        assert message in text, (case, text)


@pytest.mark.parametrize(
    "case, kwargs, error, message",
    [
        (
            "triangles in no group",
            dict(surface_groups={"Omega1": ("A",), "Omega2": ("C",), "Other": ("B",)}),
            MeshTagError,
            "triangles are in neither Omega1 nor Omega2",
        ),
        (
            "triangles in both",
            dict(surface_groups={"Omega1": ("A", "B"), "Omega2": ("B", "C")}),
            MeshTagError,
            "in more than one surface group",
        ),
        (
            "Gamma_C as a surface group",
            dict(gamma_c=(), surface_groups={"Omega1": ("A", "B"), "Omega2": ("C",), "Gamma_C": ("C",)}),
            MeshTagError,
            "'Gamma_C' is a surface group (dimension [2]); it must be a curve group",
        ),
        (
            "Omega2 missing",
            dict(surface_groups={"Omega1": ("A", "B", "C")}),
            MeshTagError,
            "lacks the physical group(s) ['Omega2']",
        ),
        ("mesh off the plane z = 0", dict(z=0.5), InputError, "z ≠ 0 (largest |z| = 0.5)"),
    ],
)
def test_bad_groups_and_geometry_are_refused_before_the_mesh_is_built(tmp_path, case, kwargs, error, message):
    path = build_columns(tmp_path / "bad.msh", **kwargs)
    with pytest.raises(error) as info:
        read_mesh(path)
    assert message in str(info.value), (case, str(info.value))


@pytest.mark.parametrize(
    "content, message",
    [
        ("tetrahedra", "4-node tetrahedra only"),  # (second-order ones)
        ("quadrangles", "needs 3-node triangles only"),
        ("", "cannot read"),
        ("not a mesh\n", "cannot read"),
        ("$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$Nodes\n1 2 1 2\n", "cannot read"),
    ],
)
def test_unreadable_or_wrong_kind_of_file(tmp_path, content, message):
    path = tmp_path / "bad.msh"
    if content in ("tetrahedra", "quadrangles"):
        _solid_or_quads(path, content)
    else:
        path.write_text(content)
    with pytest.raises(InputError, match=message):
        read_mesh(path)


def test_a_directory_or_bad_H_is_refused(tmp_path):
    with pytest.raises(InputError, match="not a file"):
        read_mesh(tmp_path)
    path = build_columns(tmp_path / "good.msh")
    for H in (0, -0.25, float("nan"), float("inf"), "1/4"):
        with pytest.raises(InputError, match="coarse size H"):
            read_mesh(path, H=H)
    # any positive H is a grid of squares over the bounding box; cells that straddle its lines lie in no
    # coarse cell (-1), which the multiscale methods refuse (test_coarse_partition)
    assert np.any(read_mesh(path, H=0.3).coarse_cell < 0)


def test_a_part_not_held_by_gamma_d_and_extra_rules():
    """The rules on plain arrays: a floating part, and a rule added for a new group (as Gamma_N will be)."""
    # two unit squares, each cut into two triangles; the right one (x in [2, 3]) touches nothing
    pts = np.array([[0, 0], [1, 0], [1, 1], [0, 1], [2, 0], [3, 0], [3, 1], [2, 1]], dtype=float)
    tri = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]])
    desc = MeshDescription(
        pts,
        tri,
        np.array([1, 2, 1, 1]),
        {
            "gamma": np.array([[0, 2]]),
            "Gamma_C": np.array([[2, 3]]),
            "Gamma_D": np.array([[0, 1]]),
            "Gamma_N": np.array([[0, 1], [5, 6]]),
        },
    )
    problems = mesh_problems(desc)
    assert any("do not touch 'Gamma_D'" in p for p in problems), problems
    assert any("'Gamma_C' touches 'gamma'" in p for p in problems), problems
    assert not any("Gamma_N" in p for p in problems), "unknown groups are ignored"
    rules = (*BOUNDARY_RULES, BoundaryRule("Gamma_N", required=False, disjoint_from=("Gamma_D", "Gamma_C")))
    assert any("'Gamma_N' and 'Gamma_D' share 1 segments" in p for p in mesh_problems(desc, rules))


def test_describe_contact_mesh_matches_the_builder():
    cm = unit_square(8, 4)
    desc = describe_contact_mesh(cm)
    assert desc.triangles.shape == (128, 3) and desc.points.shape == (81, 2)
    assert sorted(np.bincount(desc.label).tolist()) == [0, 32, 96]
    assert {k: v.shape[0] for k, v in desc.facets.items()} == {"Gamma_D": 24, "Gamma_C": 8, "gamma": 8}
    assert mesh_problems(desc) == []
