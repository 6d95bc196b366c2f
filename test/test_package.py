"""
The package as ROS 2 users get it: ``colcon build`` of the ament_python package, then ``ros2 run``.

``ros2 run rotation_node <exe>`` runs ``<install>/rotation_node/lib/rotation_node/<exe>``
with the package's site-packages on PYTHONPATH (what sourcing ``install/setup.bash``
does); these tests build a copy of the sources with colcon and run that file.
"""
import os
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ElementTree

import pytest

from ros_harness import RosProcess, TestNode

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
EXECUTABLES = ('rotation_node', 'rotation_bag', 'rotation_scene', 'rotation_bench')
SITE = os.path.join('lib', f'python{sys.version_info[0]}.{sys.version_info[1]}', 'site-packages')


@pytest.fixture(scope='module')
def colcon_install(tmp_path_factory):
    """Build a copy of the package with colcon; return its install prefix."""
    workspace = tmp_path_factory.mktemp('colcon_ws')
    shutil.copytree(ROOT, workspace / 'src' / 'rotation_node', ignore=shutil.ignore_patterns(
        '.git', '.venv', 'build', 'install', 'log', '__pycache__', '*.egg-info',
        '.pytest_cache', '.hypothesis', '*.mcap', '*.png'))
    colcon = os.path.join(os.path.dirname(sys.executable), 'colcon')
    result = subprocess.run(
        [colcon, 'build', '--base-paths', 'src', '--build-base', 'build',
         '--install-base', 'install', '--event-handlers', 'console_direct-'],
        cwd=workspace, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stdout + result.stderr
    return workspace / 'install' / 'rotation_node'


def test_colcon_build_installs_what_ros2_run_needs(colcon_install):
    for exe in EXECUTABLES:
        path = colcon_install / 'lib' / 'rotation_node' / exe
        assert path.is_file() and os.access(path, os.X_OK), exe
    share = colcon_install / 'share'
    assert (share / 'ament_index' / 'resource_index' / 'packages' / 'rotation_node').is_file()
    assert (share / 'rotation_node' / 'package.xml').is_file()
    assert (share / 'rotation_node' / 'config' / 'params.yaml').is_file()
    assert list((share / 'rotation_node' / 'config' / 'scenes').glob('*.yaml'))
    assert (colcon_install / SITE / 'rotation_node' / 'conversions' / '__init__.py').is_file()
    assert (colcon_install / SITE / 'rotation_node' / 'py.typed').is_file()   # PEP 561


def test_package_xml_is_format_3_ament_python():
    root = ElementTree.parse(os.path.join(ROOT, 'package.xml')).getroot()
    assert root.get('format') == '3'
    assert root.findtext('name') == 'rotation_node'
    assert root.find('export').findtext('build_type') == 'ament_python'
    depends = {e.text for e in root.findall('exec_depend')}
    assert {'rclpy', 'geometry_msgs', 'sensor_msgs', 'nav_msgs', 'diagnostic_msgs',
            'python3-numpy', 'python3-numba'} <= depends


def test_installed_node_starts_and_stops_on_ctrl_c(colcon_install):
    env = {'PYTHONPATH': os.pathsep.join(filter(None, [str(colcon_install / SITE),
                                                       os.environ.get('PYTHONPATH')]))}
    exe = colcon_install / 'lib' / 'rotation_node' / 'rotation_node'
    with TestNode() as client, RosProcess([exe], env=env) as node:
        appeared = client.spin_until(
            lambda: 'rotation_node' in client.node.get_node_names(), timeout=60)
        assert appeared, node.stop()
        assert node.stop() == 0, node.output
