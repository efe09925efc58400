"""Stiffness sampling for the scans in bench/ (panel_deploy.bench.sampling)."""

from pathlib import Path

import numpy as np
import pytest

from panel_deploy.bench.sampling import group_limits, latin_hypercube, neighbourhood
from panel_deploy.build import build_model
from panel_deploy.errors import OptimisationError
from panel_deploy.optimise import StiffnessProblem
from panel_deploy.scene import load_scene

PAPER = Path(__file__).resolve().parent.parent / "config" / "scenes" / "paper_4x4.yaml"


@pytest.fixture(scope="module")
def problem():
    return StiffnessProblem.from_model(build_model(load_scene(PAPER)), (0.001, 0.2), 0.1)


def test_neighbourhood_is_centred_on_k_and_clipped_to_the_bounds(problem):
    k = problem.k_of(np.log10([0.1, 0.0012, 0.1, 0.1, 0.19, 0.1, 0.1]))
    lo, hi = neighbourhood(problem, k, 0.1)
    np.testing.assert_allclose(lo[[0, 4]], [-1.1, np.log10(0.19) - 0.1])
    np.testing.assert_allclose(hi[[0, 1]], [-0.9, np.log10(0.0012) + 0.1])
    assert lo[1] == pytest.approx(-3.0) and hi[4] == pytest.approx(np.log10(0.2))
    with pytest.raises(OptimisationError, match="^spread: "):
        neighbourhood(problem, k, 0.0)


def test_group_limits_take_any_hinge_of_the_group(problem):
    limits = group_limits(problem, ["r1c3-r1c4=0.05", "r3c2-r4c2=0.09"], 0.001)
    assert limits[0] == 0.05 and limits[5] == 0.09  # r1c3-r1c4 shares group 0 with r1c1-r1c2
    assert np.count_nonzero(limits == 0.001) == problem.n - 2
    with pytest.raises(OptimisationError, match="no hinge named 'nope'"):
        group_limits(problem, ["nope=0.1"], 0.001)
    with pytest.raises(OptimisationError, match="expected HINGE=K"):
        group_limits(problem, ["r1c1-r1c2=soft"], 0.001)


def test_latin_hypercube_fills_every_stratum_of_the_box(problem):
    lo, hi = np.full(problem.n, -2.0), np.full(problem.n, -1.0)
    ks = latin_hypercube(problem, lo, hi, 10, seed=4)
    x = np.array([problem.x_of(k) for k in ks])
    assert x.shape == (10, problem.n) and np.all((x >= -2.0) & (x <= -1.0))
    for column in x.T:  # one sample in each tenth of every axis
        assert sorted(np.floor((column + 2.0) * 10).astype(int)) == list(range(10))
    for k in ks:  # a group's hinges share their value
        assert all(k[i] == k[g[0]] for g in problem.groups for i in g)
