"""The text summary of a deployment (panel_deploy.summary)."""

from panel_deploy.summary import deployment_text


def summary(time_to_flat, t_collision):
    return {"success": True, "message": "reached t_end", "method": "compiled", "closure": "penalty",
            "t_end": 2.0, "wall_time": 1.0, "nsteps": 10, "nfev": 50, "flat_tolerance": 0.05,
            "time_to_flat": time_to_flat, "energy_balance_error": 1e-6, "max_constraint_gap": 1e-4,
            "min_closure_sigma": None, "release_times": {"h0": 0.01}, "locked_hinges": [],
            "collision": {"first_collision": {"t": t_collision, "pair": ["A", "B"]},
                          "d": 0.05, "v": 0.04}}


def test_a_collision_after_the_first_flat_is_marked_as_after_the_deployment():
    text = deployment_text(summary(0.835, 0.8358))
    assert "first collision at 0.8358 s (after the array first lay flat" in text


def test_a_collision_before_flat_or_without_flat_is_not():
    for flat in (0.9, None):
        line = deployment_text(summary(flat, 0.8358)).splitlines()[-1]
        assert line.startswith("first collision at 0.8358 s between A and B")


def test_the_scheme_is_named_where_it_is_not_the_method():
    s = summary(None, 0.5)
    for scheme, line in ((None, "method compiled, closure penalty"),   # older recordings
                         ("compiled", "method compiled, closure penalty"),
                         ("dopri5, then ros34pw2 from t = 0.0707 s",
                          "method compiled (dopri5, then ros34pw2 from t = 0.0707 s), closure penalty")):
        s["scheme"] = scheme
        assert deployment_text(s).splitlines()[1].startswith(line + ", simulated to 2 s")


def test_energy_balance_is_flagged_when_large_and_withheld_when_meaningless():
    s = summary(None, 0.5)
    for error, shown in ((1e-6, "energy balance error 1.00e-06 (relative);"),
                         (0.26, "2.60e-01 (relative) -- LARGE (above 0.01)"),
                         (None, "energy balance error not meaningful")):
        s["energy_balance_error"] = error
        assert shown in deployment_text(s)


def test_zero_energy_run_reports_no_balance_error(capsys):
    import json

    from panel_deploy.cli import main
    code = main(["simulate", "paper_4x4", "--t-end", "0.02", "--method", "compiled", "--json",
                 "--set", "hinges.stiffness=0", "--set", "gravity=[0, 0, 0]"])
    out = json.loads(capsys.readouterr().out)
    assert code == 0 and out["energy_balance_error"] is None  # was 1.6e17


def test_a_failed_runs_collision_is_not_passed_off_as_a_result():
    # issue 26: a run stopped by its step budget reported v = 8388 m/s as it would a result
    s = summary(None, 0.0012)
    s.update(success=False, message="step budget exhausted at t = 0.0013 s")
    text = deployment_text(s)
    assert text.startswith("FAILED: step budget exhausted")
    assert text.splitlines()[-1].endswith("d = 0.05 m (up to the failure: not a result)")
    s["collision"]["first_collision"] = None
    assert deployment_text(s).splitlines()[-1] == ("no collision; smallest distance d = 0.05 m "
                                                   "(up to the failure: not a result)")
    assert "not a result" not in deployment_text(summary(None, 0.0012))


def test_a_run_that_does_not_keep_its_energy_fails(capsys):
    # issue 33: every damper at 0 at rtol 1e-4 exited 0 "ok" with a 26 % energy
    # balance error; now the run fails there, exit 1, saying why in its first line
    from panel_deploy.cli import main
    undamped = ["--set", "hinges.damping_ratio=0", "--set", "contact.c_s=0",
                "--set", "closure.c_M=0", "--set", "closure.c_N=0"]
    code = main(["simulate", "paper_4x4", "--t-end", "0.3", "--set", "simulation.rtol=1e-4",
                 "--set", "simulation.atol=1e-6", *undamped])
    first = capsys.readouterr().out.splitlines()[0]
    assert code == 1
    assert first.startswith("FAILED: energy balance error ") and "above 0.01 at t = " in first
