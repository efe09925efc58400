"""panel_deploy.progress: a bar in a terminal, plain lines in logs."""

import io

from panel_deploy import progress
from panel_deploy.optimise import Progress as SearchProgress
from panel_deploy.optimise import print_progress
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


def test_a_plain_line_says_how_long_is_left_at_this_pace(monkeypatch):
    clock = iter([100.0, 110.0, 110.0, 130.0, 130.0])  # start, then per update: test, line
    monkeypatch.setattr(progress.time, "monotonic", lambda: next(clock))
    monkeypatch.setattr(progress, "LINE_EVERY", 0.0)
    out = io.StringIO()
    bar = Progress(40, "optimise", "evaluations", file=out)
    bar.update(10)   # 10 of 40 in 10 s: 30 s left
    bar.update(30)   # done: nothing left to say
    first, last = out.getvalue().splitlines()
    assert first == "optimise: 10/40 evaluations, 10.0 s, 30 s left at this pace"
    assert last == "optimise: 40/40 evaluations, 30.0 s"


def test_an_optimiser_progress_line_says_how_long_its_budget_leaves():
    out = io.StringIO()
    p = SearchProgress("global", 1, 100, 1.5, True, False, 50.0)
    print_progress(p, out, budget=400)
    print_progress(p, out)
    with_budget, without = out.getvalue().splitlines()
    assert with_budget.endswith("50.0 s, 150 s left at this pace") and without.endswith("50.0 s")


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
