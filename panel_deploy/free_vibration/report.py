"""A calibration from several swings: both analyses of every test, pooled; the
scene's ``calibration`` record, the calibrated scene and the report text.
"""

from __future__ import annotations

from dataclasses import dataclass


from .estimate import LEVEL, Estimate, fit_swing, log_decrement, pool


@dataclass(frozen=True)
class Calibration:
    """Every test analysed both ways and the tests pooled.

    ``tests`` holds ``(log_decrement, fit)`` per recording; ``fit`` and
    ``log_decrement`` map "c", "k", "ratio" (and the fit "drag", when some
    test identified it) to their :class:`Pooled` over the tests that
    succeeded; empty when none did.
    """

    tests: tuple
    fit: dict
    log_decrement: dict

    @property
    def success(self) -> bool:
        return "ratio" in self.fit


def _pooled(analyses, names) -> dict:
    out = {}
    for name in names:
        found = [getattr(a, name) for a in analyses if a.success and getattr(a, name) is not None]
        if found:
            out[name] = pool(found)
    return out


def calibrate(readings) -> Calibration:
    """Analyse ``readings`` (``(swing, rig, peaks)`` from :func:`read_swing`)
    by log decrement and by fit, and pool them."""
    tests = []
    for swing, rig, peaks in readings:
        decrement = log_decrement(swing, rig, peaks)
        tests.append((decrement, fit_swing(swing, rig, peaks, decrement)))
    return Calibration(tuple(tests), _pooled([f for _, f in tests], ("c", "k", "ratio", "drag")),
                       _pooled([d for d, _ in tests], ("c", "k", "ratio")))
#: Units of the figures (c and k of one spring).
UNITS = {"c": "N m s/rad", "k": "N m/rad", "ratio": "s", "drag": ""}


LABELS = {"c": "c", "k": "k", "ratio": "c/k", "drag": "C_d"}


def calibration_record(cal: Calibration, hinge: str | None = None) -> dict:
    """The ``calibration`` section of a calibrated scene (plain values, YAML
    and JSON alike): the pooled fit with its intervals and agreement, the
    pooled log decrement, and every test."""
    def pooled(found):
        return {name: {**p.estimate.figures(), "unit": UNITS[name], "chi2": round(p.chi2, 3),
                       "dof": p.dof, "p": round(p.p, 4), "widened": p.widened}
                for name, p in found.items()}

    tests = []
    for decrement, fit in cal.tests:
        test = {"recording": fit.source, "peaks": fit.peaks}
        for a in (fit, decrement):
            key = "fit" if a is fit else "log_decrement"
            test[key] = ({name: getattr(a, name).figures() for name in ("c", "k", "ratio", "drag")
                          if getattr(a, name) is not None} if a.success else {"failed": a.message})
            if a.success:
                test[key].update({"zeta": float(f"{a.zeta:.6g}"),
                                  "rms_rad" if a is fit else "scatter_ln": float(f"{a.rms:.3g}")})
            if a.notes:
                test[key]["notes"] = list(a.notes)
        tests.append(test)
    return {"method": "free vibration: fit of the one-hinge model's free response (log "
                      "decrement beside it); c and k of one spring",
            "confidence": LEVEL,
            **({"hinge": hinge} if hinge else {}),
            "fit": pooled(cal.fit), "log_decrement": pooled(cal.log_decrement), "tests": tests}


def calibrated_scene(data: dict, cal: Calibration, hinge: str | None = None) -> dict:
    """Scene ``data`` with the pooled fit's damping: ``hinges.damping_ratio``
    = c/k, or with ``hinge`` that hinge's ``hinges.damping_overrides`` entry =
    c (N m s/rad, one spring); and :func:`calibration_record` as the
    ``calibration`` section's ``free_vibration`` entry, beside what other
    calibrations of the scene wrote there."""
    out = dict(data)
    hinges = dict(out.get("hinges") or {})
    if hinge is None:
        hinges["damping_ratio"] = cal.fit["ratio"].estimate.figures()["value"]
    else:
        hinges["damping_overrides"] = {**(hinges.get("damping_overrides") or {}),
                                       hinge: cal.fit["c"].estimate.figures()["value"]}
    out["hinges"] = hinges
    out["calibration"] = {**(out.get("calibration") or {}),
                          "free_vibration": calibration_record(cal, hinge)}
    return out


def _line(label, e: Estimate, unit="") -> str:
    return f"  {label:<6} {e.text()} {unit}".rstrip()


def report_text(cal: Calibration) -> str:
    """The human report: every test both ways, then the pooled figures."""
    lines = []
    for decrement, fit in cal.tests:
        lines.append(f"{fit.source}: {fit.peaks} peaks")
        for a in (decrement, fit):
            if not a.success:
                lines.append(f"  {a.method}: failed: {a.message}")
                continue
            spread = (f"residual {a.rms:.2g} rad RMS" if a is fit
                      else f"ln amplitude scatter {a.rms:.2g}")
            lines.append(f"  {a.method}: zeta {a.zeta:.4g}, equilibrium {a.equilibrium:.4g} rad, "
                         f"{spread}")
            lines += ["  " + _line(LABELS[n], getattr(a, n), UNITS[n])
                      for n in ("c", "k", "ratio", "drag") if getattr(a, n) is not None]
            lines += [f"    note: {note}" for note in a.notes]
    for title, found in (("fit", cal.fit), ("log decrement", cal.log_decrement)):
        if not found:
            lines.append(f"pooled {title}: no test succeeded")
            continue
        lines.append(f"pooled {title} ({found['c'].dof + 1} tests, {LEVEL:.0%} intervals):")
        for name, p in found.items():
            verdict = ("" if p.dof == 0 else
                       f"  chi2 {p.chi2:.3g} on {p.dof}, p {p.p:.3g}"
                       + (": the tests disagree, interval widened" if p.widened else ""))
            lines.append(_line(LABELS[name], p.estimate, UNITS[name]) + verdict)
    return "\n".join(lines)
