"""
The launch files (``launch/``): their arguments, the node they start, its parameters.

``ros2 launch`` itself is not available without a ROS install (``launch`` and
``launch_ros`` are not on PyPI); each file is loaded with recording stand-ins
for the launch API (``launch_stubs``), evaluated for given launch arguments, and
the parameters it gives the node - its parameters file plus the overrides from
the arguments - are validated with ``rotation_node.parameters`` for the node's
fully qualified name, as rcl would match them.
"""
from importlib import metadata
from pathlib import Path

from launch_stubs import declared_arguments, launch_description, launched_nodes
import pytest
from rotation_node.parameters import NodeParameters, parameters_from_yaml

ROOT = Path(__file__).resolve().parent.parent
#: The source tree has the layout of ``share/rotation_node`` (config/, launch/).
SHARE = {'rotation_node': ROOT}

#: The arguments each launch file declares (and documents in its docstring).
ARGUMENTS = {
    'rotation_node.launch.py': ('input_topic', 'input_type', 'params_file', 'namespace'),
    'tf_euler.launch.py': ('parent_frame', 'child_frame', 'params_file', 'namespace'),
}


def _load(name, share=None):
    return launch_description(ROOT / 'launch' / name, share or SHARE)[0]


def _node_parameters(node):
    """Return the node's parameters as rcl resolves them: its parameters file, then overrides."""
    fq_name = '/'.join(('', *filter(None, [node.namespace.strip('/')]), node.name))
    params_file, *overrides = node.parameters
    assert Path(params_file).is_file(), f'parameters file {params_file} does not exist'
    resolved = parameters_from_yaml(params_file, fq_name)
    for values in overrides:
        resolved = resolved.replaced(values)
    return resolved


def test_every_launch_file_is_listed_here():
    assert sorted(p.name for p in (ROOT / 'launch').glob('*.launch.py')) == sorted(ARGUMENTS)


@pytest.mark.parametrize('name', sorted(ARGUMENTS))
def test_launch_file_declares_and_documents_its_arguments(name):
    description, namespace = launch_description(ROOT / 'launch' / name, SHARE)
    declared = declared_arguments(description)
    assert tuple(declared) == ARGUMENTS[name]
    for argument in declared.values():
        assert argument.description, argument.name
        assert f'``{argument.name}``' in namespace['__doc__'], argument.name


@pytest.mark.parametrize('name', sorted(ARGUMENTS))
def test_launch_file_starts_the_installed_executable(name):
    executables = {e.name for e in metadata.distribution('rotation_node').entry_points
                   if e.group == 'console_scripts'}
    nodes = launched_nodes(_load(name))
    assert [(n.package, n.executable, n.name) for n in nodes] == [
        ('rotation_node', 'rotation_node', 'rotation_node')]
    assert nodes[0].executable in executables


def test_unknown_launch_argument_is_refused():
    with pytest.raises(KeyError, match='input_topc'):
        launched_nodes(_load('rotation_node.launch.py'), {'input_topc': '/imu'})


@pytest.mark.parametrize('namespace', ['', 'imu', '/robot1/imu'])
def test_rotation_node_launch_defaults_validate(namespace):
    (node,) = launched_nodes(_load('rotation_node.launch.py'), {'namespace': namespace})
    assert node.remappings == [('input', '/imu')]
    assert node.namespace == namespace
    # config/params.yaml (the defaults) names the node in any namespace.
    assert _node_parameters(node) == NodeParameters()


def test_rotation_node_launch_arguments_reach_the_node(tmp_path):
    params = tmp_path / 'mine.yaml'
    params.write_text('/**/rotation_node:\n  ros__parameters:\n    input_type: pose\n'
                      '    outputs: [quaternion, euler]\n')
    (node,) = launched_nodes(_load('rotation_node.launch.py'), {
        'input_topic': '/camera/pose', 'params_file': str(params), 'namespace': 'camera'})
    assert node.remappings == [('input', '/camera/pose')]
    resolved = _node_parameters(node)
    assert (resolved.input_type, resolved.outputs) == ('pose', ('quaternion', 'euler'))

    (node,) = launched_nodes(_load('rotation_node.launch.py'), {
        'input_type': 'odometry', 'params_file': str(params), 'namespace': 'camera'})
    assert _node_parameters(node).input_type == 'odometry'


@pytest.mark.parametrize('namespace', ['', 'robot1'])
def test_tf_euler_launch_defaults_validate(namespace):
    (node,) = launched_nodes(_load('tf_euler.launch.py'), {'namespace': namespace})
    resolved = _node_parameters(node)
    assert (resolved.input_type, resolved.outputs) == ('tf', ('euler',))


def test_tf_euler_launch_frames_reach_the_node():
    (node,) = launched_nodes(_load('tf_euler.launch.py'),
                             {'parent_frame': 'odom', 'child_frame': 'imu_link'})
    assert node.parameters[1] == {'tf.parent_frame': 'odom', 'tf.child_frame': 'imu_link'}
    _node_parameters(node)
