"""Every node executable ends on SIGINT and SIGTERM with exit code 0, fast and without a traceback."""

import signal

import pytest

from ros_harness import Client, NodeProcess, wait_for

NODES = ("array_model", "dynamics", "collision_monitor", "optimiser")


@pytest.fixture(scope="module")
def client(compiled_nodes):
    c = Client("signal_test")
    yield c
    c.close()


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
@pytest.mark.parametrize("node", NODES)
def test_signal_ends_the_node_cleanly(client, node, sig):
    name = f"{node}_{sig.name}"  # a name of its own: not another test's process
    proc = NodeProcess(node, node_name=name)
    wait_for(lambda: client.has_node(name), timeout=60, what=f"{node} to start")
    code, seconds, err = proc.stop(sig)
    # A node that hangs is killed after stop's 10 s (exit != 0); one that ended
    # cleanly took 2.08 s once on 2 loaded cores in CI: 5 s still tells them apart.
    assert code == 0 and seconds < 5.0 and "Traceback" not in err, (code, seconds, err)
