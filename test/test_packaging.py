"""Packaging: executables, launch file, params.yaml, package.xml, import rules, build requirements."""

import ast
import subprocess
import sys
import tomllib
from pathlib import Path
from xml.etree import ElementTree

import yaml

ROOT = Path(__file__).resolve().parent.parent
NODES = ("array_model", "dynamics", "collision_monitor", "optimiser")
THIRD_PARTY = {"numpy", "scipy", "yaml", "panel_deploy"}


def imported_top_modules(paths):
    found = set()
    for path in paths:
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                found |= {a.name.split(".")[0] for a in node.names}
            elif isinstance(node, ast.ImportFrom) and node.level == 0:
                found.add(node.module.split(".")[0])
    return found - set(sys.stdlib_module_names) - THIRD_PARTY


def test_every_node_executable_is_installed():
    for name in NODES + ("panel-deploy",):
        assert (Path(sys.executable).parent / name).exists(), name


def test_launch_file_compiles_and_names_installed_executables():
    source = (ROOT / "launch" / "panel_deploy.launch.py").read_text()
    compile(source, "panel_deploy.launch.py", "exec")
    tree = ast.parse(source)
    nodes = next(n.value for n in tree.body if isinstance(n, ast.Assign)
                 and getattr(n.targets[0], "id", "") == "NODES")
    assert tuple(ast.literal_eval(nodes)) == NODES
    arguments = {c.args[0].value for c in ast.walk(tree) if isinstance(c, ast.Call)
                 and getattr(c.func, "id", "") == "DeclareLaunchArgument"}
    assert arguments == {"scene", "rate_hz", "real_time_factor", "use_sim_time", "namespace",
                         "frame_prefix"}


def test_params_yaml_keys_are_declared_parameters():
    from panel_deploy.nodes import load
    params = yaml.safe_load((ROOT / "config" / "params.yaml").read_text())
    assert set(params) == {f"/**/{name}" for name in NODES}  # in any namespace
    for name in NODES:
        declared = load(name).PARAMETERS
        given = params[f"/**/{name}"]["ros__parameters"]
        assert set(given) <= set(declared), set(given) - set(declared)
        for key, value in given.items():
            default = declared[key][0]
            assert value == default, (name, key)  # the file documents the defaults


def test_package_xml_exec_depends_are_exactly_the_ros_imports():
    root = ElementTree.parse(ROOT / "package.xml").getroot()
    ros_depends = {e.text for e in root.findall("exec_depend") if not e.text.startswith("python3-")}
    imports = imported_top_modules([*(ROOT / "panel_deploy" / "nodes").glob("*.py"),
                                    *(ROOT / "launch").glob("*.py")])
    # the nodes import the contract's message types by name (nodes.messages.message_class)
    from panel_deploy import contract
    imports |= {t.type.split("/")[0] for t in contract.TOPICS}
    imports |= {s.type.split("/")[0] for s in contract.SERVICES}
    assert ros_depends == imports


def test_the_core_never_imports_ros():
    core = [p for p in (ROOT / "panel_deploy").rglob("*.py") if "nodes" not in p.parts]
    ros = {"rclpy", "std_msgs", "sensor_msgs", "diagnostic_msgs", "visualization_msgs",
           "geometry_msgs", "rosgraph_msgs", "std_srvs", "rcl_interfaces", "builtin_interfaces",
           "launch", "launch_ros", "tf2_msgs"}
    for path in core:
        assert not imported_top_modules([path]) & ros, path


def test_ros_command_without_rclpy_says_how_to_install(tmp_path):
    code = ("import sys; sys.modules['rclpy'] = None; from panel_deploy.cli import main; "
            "sys.exit(main(['run', 'paper_4x4']))")
    # cwd: the package under test, not the checkout that ``-c`` would import
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                          cwd=tmp_path)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert proc.stderr.strip().splitlines() == [proc.stderr.strip()]
    assert 'pip install "panel_deploy[ros]"' in proc.stderr


def _install_requires():
    call = next(node for node in ast.walk(ast.parse((ROOT / "setup.py").read_text()))
                if isinstance(node, ast.Call) and getattr(node.func, "id", "") == "setup")
    (requires,) = [k.value for k in call.keywords if k.arg == "install_requires"]
    return ast.literal_eval(requires)


def test_build_requires_are_the_run_time_requirements():
    # the build runs the package to compile its kernels (setup.py, BuildWithKernels)
    build = tomllib.loads((ROOT / "pyproject.toml").read_text())["build-system"]["requires"]
    assert sorted(r for r in build if not r.startswith("setuptools")) == sorted(_install_requires())


def _module_graph():
    """Top-level imports between the package's modules (a function's own imports,
    taken when it runs, are not edges)."""
    import networkx as nx

    root = ROOT / "panel_deploy"

    def name(path):
        parts = list(path.relative_to(ROOT).with_suffix("").parts)
        return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)

    modules = {name(p): p for p in root.rglob("*.py")}
    graph = nx.DiGraph()
    for module, path in modules.items():
        package = module if path.name == "__init__.py" else module.rsplit(".", 1)[0]
        for node in ast.parse(path.read_text()).body:
            if not isinstance(node, ast.ImportFrom):
                continue
            base = package.split(".")[:len(package.split(".")) - node.level + 1] if node.level \
                else []
            source = ".".join(base + ([node.module] if node.module else []))
            for alias in node.names:
                target = f"{source}.{alias.name}"
                target = target if target in modules else source
                if target in modules and target != module:
                    graph.add_edge(module, target)
    return graph


def test_no_import_cycles_and_data_flows_one_way():
    import networkx as nx

    graph = _module_graph()
    assert graph.has_edge("panel_deploy.nodes.recorder", "panel_deploy.record.writer")  # it sees
    assert list(nx.simple_cycles(graph)) == []
    record = {m for m in graph if m.startswith("panel_deploy.record")}
    nodes = [m for m in graph if m.startswith("panel_deploy.nodes")]
    # the nodes reach the recording code through its writer only
    assert {t for m in nodes for t in graph.successors(m) if t in record} <= \
        {"panel_deploy.record.writer"}
    # the core below the recording never imports it
    for module in ("panel_deploy.model", "panel_deploy.scene", "panel_deploy.dynamics.simulate",
                   "panel_deploy.collision.check", "panel_deploy.contract"):
        assert not nx.descendants(graph, module) & record, module
