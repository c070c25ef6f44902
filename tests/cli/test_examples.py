"""``fenics-contact examples DIR``: the example folders copied into a new or empty folder, never over files."""

import pytest

from fenics_contact.cli import main
from fenics_contact.examples import EXAMPLE_DIRS, copy_examples, example_files


def test_the_example_files_are_found():
    root = example_files()
    assert all((root / name).is_dir() for name in EXAMPLE_DIRS)
    assert (root / "cases" / "composite.toml").is_file() and (root / "cases" / "composite.msh").is_file()


def test_copy_into_a_new_folder(tmp_path):
    written = copy_examples(tmp_path / "new" / "examples")
    assert {p.relative_to(tmp_path / "new" / "examples").parts[0] for p in written} == set(EXAMPLE_DIRS)
    assert all(p.is_file() and "__pycache__" not in p.parts for p in written)
    assert (tmp_path / "new" / "examples" / "demos" / "demo_primal_hybrid.py").is_file()


def test_an_empty_folder_is_accepted(tmp_path):
    assert copy_examples(tmp_path)


@pytest.mark.parametrize("existing", ["a file inside", "a file"])
def test_nothing_is_overwritten(tmp_path, existing, capsys):
    target = tmp_path / "target"
    if existing == "a file":
        target.write_text("mine")
    else:
        target.mkdir()
        (target / "notes.txt").write_text("mine")
    with pytest.raises(FileExistsError, match="give a new or empty folder"):
        copy_examples(target)
    assert main(["examples", str(target)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"error: {target} is ")
    assert sorted(p.name for p in tmp_path.rglob("*")) == (
        ["target"] if existing == "a file" else ["notes.txt", "target"]
    )
