"""A mesh far beyond the machine's memory is refused before gmsh tries to make it (it would run out of memory,
or the process be killed, after minutes)."""

import subprocess
import sys
import time

import pytest

import fenics_contact as fc
from fenics_contact.errors import InputError
from fenics_contact.problem.meshes import bulged_square, composite_block, hertz_block


def test_a_unit_square_beyond_memory_is_refused_at_once():
    start = time.perf_counter()
    with pytest.raises(InputError, match=r"h = 1/20000 has about 4e\+08 vertices .* GB of memory"):
        fc.unit_square(20000, 4)
    assert time.perf_counter() - start < 1.0


def test_a_hertz_block_refined_beyond_memory_is_refused_and_the_default_estimate_is_close():
    with pytest.raises(InputError, match="choose a coarser mesh"):
        hertz_block(0.2, refinement=1000)
    cm, _ = hertz_block(0.2)  # the estimate (3.2e3 vertices) is within a factor 2 of the mesh made
    assert 1.6e3 < cm.mesh.topology.index_map(0).size_global < 3.2e3


def test_a_bulged_square_or_a_composite_block_beyond_memory_is_refused_and_the_estimates_are_close():
    with pytest.raises(InputError, match="the bulged square with h = 1e-06 .* choose a coarser mesh"):
        bulged_square(1e-6, 0.25)
    with pytest.raises(InputError, match="the composite block .* choose a coarser mesh"):
        composite_block(0.05, refinement=1000)
    # the estimates (1.35e3 and 2.7e3 vertices) are within a factor 2 of the meshes made
    assert 0.7e3 < bulged_square(1 / 32, 0.25).mesh.topology.index_map(0).size_global < 2.7e3
    assert 1.35e3 < composite_block(0.05)[0].mesh.topology.index_map(0).size_global < 5.4e3


def test_the_command_line_refuses_it_with_exit_2():
    run = subprocess.run(
        [
            sys.executable,
            "-m",
            "fenics_contact.launch",
            "run",
            "--case",
            "cases/bar.toml",
            "--set",
            "mesh.h=20000",
            "--no-plots",
            "--out",
            "unused",
        ],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=fc.__path__[0] + "/..",
    )
    assert run.returncode == 2 and "choose a coarser mesh" in run.stderr, run.stderr


def test_a_3d_model_counts_its_vertices_in_three_dimensions():
    """The run's estimate before the mesh is made: (n + 1)³ vertices on the cube of model 4, exactly those of the
    mesh made, and within a factor 2 those of model 5's gmsh block (h = 1/12); --model 4 --h 400 (6.4e7
    vertices) is refused, which a planar count, (n + 1)² = 1.6e5 vertices, would have let through."""
    import os

    from fenics_contact.cli import RunOptions
    from fenics_contact.cli.outputs import RUN_BYTES_PER_VERTEX, check_run_memory, run_vertices
    from fenics_contact.problem.composite3d import fibre_block_3d_mesh
    from fenics_contact.problem.models3d import channels_3d_mesh

    cube = channels_3d_mesh(4, strip=0.25)
    assert run_vertices(RunOptions(model=4, h=4, H=2)) == cube.mesh.topology.index_map(0).size_global == 5**3
    block = fibre_block_3d_mesh(12).mesh.topology.index_map(0).size_global  # (the fibres add vertices at small n)
    assert 0.5 < run_vertices(RunOptions(model=5, h=12, H=4)) / block < 2.0
    assert 401**2 * RUN_BYTES_PER_VERTEX["primal"] < os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    with pytest.raises(InputError, match=r"about 6.45e\+07 vertices"):
        check_run_memory(RunOptions(model=4, h=400, H=4))
