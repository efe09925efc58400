"""The array_model node as its own process: latched URDF and scene, reload, a bad scene."""

import time

import numpy as np
import pytest
import yourdfpy
from rcl_interfaces.srv import SetParameters
from rclpy.parameter import Parameter
from std_msgs.msg import String

from panel_deploy import contract
from panel_deploy.build import build_model
from panel_deploy.kinematics import forward_kinematics
from panel_deploy.scene_text import scene_from_yaml
from panel_deploy.nodes import messages
from panel_deploy.scene import load_scene, resolve_scene
from ros_harness import Client, NodeProcess, wait_for


@pytest.fixture(scope="module")
def node(compiled_nodes):
    proc = NodeProcess("array_model", "scene:=paper_4x4")
    client = Client("array_model_test")
    # Join late: the node has published before this subscriber exists.
    wait_for(lambda: client.node.count_publishers("/robot_description") >= 1, timeout=60,
             what="the node")
    time.sleep(0.5)
    yield client, proc
    client.close()
    proc.stop()


def latest(client, topic):
    box = client.listen(String, topic, messages.qos(contract.LATCHED))
    wait_for(lambda: box, what=f"a message on {topic}")
    return box[-1].data


def test_late_subscriber_gets_a_urdf_whose_fk_is_the_models(node, tmp_path):
    client, _ = node
    path = tmp_path / "array.urdf"
    path.write_text(latest(client, "/robot_description"))
    urdf = yourdfpy.URDF.load(str(path), build_scene_graph=True, load_meshes=False)
    model = build_model(load_scene(resolve_scene("paper_4x4")))
    joints = [model.hinges[h].name for h in model.joints]
    rng = np.random.default_rng(7)
    worst = 0.0
    for _ in range(10):
        theta = rng.uniform(0.0, np.pi, model.n_coords)
        urdf.update_cfg(dict(zip(joints, theta)))
        R, p = forward_kinematics(model, theta)
        for i, body in enumerate(model.bodies):
            link = urdf.link_map[body.name]
            box = urdf.get_transform(body.name, "world") @ link.visuals[0].origin
            worst = max(worst, np.abs(box[:3, 3] - p[i]).max(), np.abs(box[:3, :3] - R[i]).max())
    assert worst <= 1e-9


def test_model_topic_carries_the_resolved_scene(node):
    client, _ = node
    scene = scene_from_yaml(latest(client, "/panel_deploy/model"))
    assert scene.name == "paper_4x4" and scene.array.rows == 4


def test_bad_scene_is_refused_and_the_old_model_stays(node, tmp_path):
    client, _ = node
    good = tmp_path / "mine.yaml"
    good.write_text(resolve_scene("paper_4x4").read_text().replace("name: paper_4x4", "name: mine"))
    set_param = lambda value: client.call(SetParameters, "/array_model/set_parameters",  # noqa: E731
                                          SetParameters.Request(parameters=[
                                              Parameter("scene", value=value).to_parameter_msg()])).results[0]
    refused = set_param(str(tmp_path / "missing.yaml"))
    assert not refused.successful and "scene file not found" in refused.reason
    assert set_param(str(good)).successful
    assert client.trigger("/array_model/reload").success
    wait_for(lambda: scene_from_yaml(latest(client, "/panel_deploy/model")).name == "mine",
             what="the new model")
    good.write_text(good.read_text().replace("rows: 4", "rows: -4"))
    reply = client.trigger("/array_model/reload")
    assert not reply.success and "array.rows" in reply.message and "kept the old model" in reply.message
    time.sleep(0.3)
    assert scene_from_yaml(latest(client, "/panel_deploy/model")).name == "mine"


def test_bad_scene_at_start_is_one_line_and_exit_2(tmp_path):
    proc = NodeProcess("array_model", f"scene:={tmp_path / 'nope.yaml'}")
    _, err = proc.proc.communicate(timeout=60)
    assert proc.proc.returncode == 2
    assert err.strip().splitlines()[-1].startswith("panel-deploy: error:") and "Traceback" not in err
