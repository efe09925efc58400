"""panel_deploy.progress: a bar in a terminal, plain lines in logs."""

import io

from panel_deploy import progress
from panel_deploy.progress import Progress


class Terminal(io.StringIO):
    def isatty(self):
        return True


def test_plain_lines_without_a_terminal(monkeypatch):
    monkeypatch.setattr(progress, "LINE_EVERY", 0.0)
    out = io.StringIO()
    with Progress(3, "tolerance check", "copies", file=out) as bar:
        assert not bar.live
        bar.update(2, feasible=2)
        bar.update(1)
    lines = out.getvalue().splitlines()
    assert lines[0].startswith("tolerance check: 2/3 copies, feasible 2")
    assert lines[-1].startswith("tolerance check: 3/3") and "\r" not in out.getvalue()


def test_bar_in_a_terminal():
    out = Terminal()
    with Progress(4, "optimise", "evaluations", file=out) as bar:
        assert bar.live
        bar.update(4, best_f="+0.1")
    assert "4/4" in out.getvalue() and "best_f +0.1" in out.getvalue()


def test_quiet_shows_nothing():
    out = Terminal()
    with Progress(4, "optimise", "evaluations", file=out, enabled=False) as bar:
        bar.update(4)
    assert out.getvalue() == ""
