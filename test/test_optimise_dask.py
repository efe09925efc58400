"""The same optimisation on a real local Dask cluster (loopback) matches the local run."""

import numpy as np
import pytest

distributed = pytest.importorskip("distributed")

from panel_deploy.optimise import optimise, tolerance_check  # noqa: E402
from test_optimise_search import bowl_outcome, chain_model, scene  # noqa: E402


@pytest.fixture(scope="module")
def scheduler():
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  host="127.0.0.1", dashboard_address=None) as cluster:
        yield cluster.scheduler_address


def test_dask_run_matches_local_run(scheduler):
    s = scene(max_evaluations=40)
    local = optimise(chain_model(), s, workers=1, evaluation=bowl_outcome)
    remote = optimise(chain_model(), s, dask_address=scheduler, evaluation=bowl_outcome)
    np.testing.assert_array_equal(remote.k, local.k)
    assert remote.nfev == local.nfev and remote.status == local.status
    assert [e.f for e in remote.history] == [e.f for e in local.history]
    checked = tolerance_check(chain_model(), local.k, s, n=4, dask_address=scheduler,
                              evaluation=bowl_outcome)
    assert checked.n == len(checked.evaluations) == 4


def test_a_ranking_screened_on_dask_is_the_ranking_screened_here(scheduler):
    """fold.circuit: auto's screenings on the cluster (optimise --dask) rank
    the paper's 4 x 4 circuits exactly as one after the other here."""
    from panel_deploy.ranking import rank_circuits
    from panel_deploy.optimise.parallel import task_map
    from test_ranking import SOFT, PAPER, same_ranking
    from panel_deploy.scene import load_scene

    soft = load_scene(PAPER, SOFT + ["screening.candidates=3"])
    with task_map(dask_address=scheduler) as screen:
        remote = rank_circuits(soft, task_map=screen)
    same_ranking(remote, rank_circuits(soft))
