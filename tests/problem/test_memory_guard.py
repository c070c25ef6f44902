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
