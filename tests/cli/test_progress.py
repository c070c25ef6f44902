"""Progress reporting of long loops: log lines off a terminal, a tqdm bar on one, quiet for short loops."""

import logging

import pytest

from fenics_contact.progress import Progress


def test_log_lines_count_done_and_total(caplog):
    caplog.set_level(logging.INFO, logger="fenics_contact.progress")
    with Progress(5, "patches", interval=0.0, bar=False) as bar:
        for _ in range(5):
            bar.update()
    lines = [r.getMessage() for r in caplog.records]
    assert lines[0].startswith("patches: 1/5 done")
    assert "left" in lines[0]
    assert lines[-1].startswith("patches: 5/5 done in")
    assert bar.done == 5 and bar.eta() == 0.0


def test_short_loop_is_quiet(caplog):
    caplog.set_level(logging.INFO, logger="fenics_contact.progress")
    with Progress(3, "quick", interval=60.0, bar=False) as bar:
        bar.update(3)
    assert caplog.records == []


def test_bar_on_request(capsys):
    with Progress(4, "bar", bar=True) as bar:
        bar.update(4)
    assert "4/4" in capsys.readouterr().err


def test_negative_total_refused():
    with pytest.raises(ValueError):
        Progress(-1, "bad")
