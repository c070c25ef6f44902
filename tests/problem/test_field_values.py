"""A user's field (a Python callable for E, ν or the body force) is checked where it is evaluated: a wrong shape,
an exception, complex or non-finite values are refused with the field's name, never read past or kept."""

import numpy as np
import pytest

import fenics_contact as fc
from fenics_contact.errors import InputError


@pytest.mark.parametrize(
    "load, message",
    [
        (lambda x: np.ones((2, x.shape[1] - 100)), "values of shape (2, N), got shape (2, 28) for N = 128"),
        (lambda x: np.ones(x.shape[1]), "values of shape (2, N), got shape (128,)"),
        (lambda x: np.full((2, x.shape[1]), np.inf), "is not finite at 256 value(s)"),
        (lambda x: 1 / 0, "raised ZeroDivisionError"),
        (lambda x: np.ones((2, x.shape[1])) * (1 + 1j), "must give real numbers"),
    ],
)
def test_a_bad_body_force_is_refused(load, message):
    cm = fc.unit_square(8, 2)
    with pytest.raises(InputError, match="the field f") as error:
        fc.models.model_1().with_(load=load).on(cm).fields
    assert message in str(error.value)


def test_a_bad_youngs_modulus_is_refused_and_a_good_one_kept():
    cm = fc.unit_square(8, 2)
    with pytest.raises(InputError, match=r"the field E .*got shape \(1, 128\)"):
        fc.models.model_1().with_(youngs_modulus=lambda x: np.ones((1, x.shape[1]))).on(cm).fields
    fields = fc.models.model_1().with_(youngs_modulus=lambda x: 2.0 + x[0]).on(cm).fields
    E = fields.E.x.array  # 2 + x at the cell midpoints of the 8 × 8 grid: x = (2k + 1)/24 or (2k + 2)/24 (k < 8)
    assert 2.0 < E.min() < 2.1 and 2.9 < E.max() < 3.0


def test_a_pixel_map_that_does_not_cover_the_mesh_is_refused(tmp_path, capsys):
    """A map of E whose extent leaves part of the mesh uncovered is refused (exit 2), not extrapolated."""
    from fenics_contact.cli import main

    np.save(tmp_path / "E.npy", np.ones((4, 4)))
    case = tmp_path / "half.toml"
    case.write_text(
        '[mesh]\nbuiltin = "unit-square"\nh = 8\nH = 2\nclamped = ["left"]\n'
        '[material]\nE = {pixels = "E.npy", extent = [0.0, 0.5, 0.0, 1.0]}\nnu = 0.3\n'
        "[load]\nbody-force = [1.0, 0.0]\n"
    )
    assert main(["run", "--case", str(case), "--no-plots", "--out", str(tmp_path / "out")]) == 2
    assert "covers x in [0, 0.5], y in [0, 1], but the mesh spans x in [0, 1]" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


def test_a_case_file_with_a_byte_order_mark_reads_and_a_subnormal_modulus_is_refused(tmp_path):
    """Editors on some systems write a UTF-8 BOM: the file reads as without it. A subnormal number (1e-320) would pass
    as > 0 and end in NaN: a Young's modulus of 1e-320 is refused with the smallest normal number named."""
    from fenics_contact.problem.case import load_case

    text = (
        '[mesh]\nbuiltin = "unit-square"\nh = 8\nH = 2\nclamped = ["left"]\n[material]\nE = 1.0\nnu = 0.3\n'
        "[load]\nbody-force = [1.0, 0.0]\n"
    )
    (tmp_path / "bom.toml").write_bytes(b"\xef\xbb\xbf" + text.encode())
    (tmp_path / "plain.toml").write_text(text)
    assert load_case(tmp_path / "bom.toml").to_dict()["mesh"] == load_case(tmp_path / "plain.toml").to_dict()["mesh"]
    (tmp_path / "tiny.toml").write_text(text.replace("E = 1.0", "E = 1e-320"))
    with pytest.raises(InputError, match=r"material.E.*at least 2.23e-308"):
        load_case(tmp_path / "tiny.toml")
