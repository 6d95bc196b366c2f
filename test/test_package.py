"""
The package as users get it: ``colcon build`` for ROS users, ``pip install .``, and package.xml.

``ros2 run rotation_node <exe>`` runs ``<install>/rotation_node/lib/rotation_node/<exe>``
with the package's site-packages on PYTHONPATH (what sourcing ``install/setup.bash``
does); these tests build a copy of the sources with colcon and run that file. A
non-editable ``pip install`` of another copy runs every installed executable. Both
run with the test oracles (scipy, transforms3d, mpmath) made unimportable: the
runtime package must not need them. package.xml is checked against what the runtime
package and the launch files import, and against the rosdep keys that exist.
"""
import ast
import functools
import json
import os
from pathlib import Path
import re
import shutil
import subprocess
import sys
import time
import xml.etree.ElementTree as ElementTree

from launch_stubs import launch_description, launched_nodes
import numpy as np
import pytest
from ros_harness import RosProcess, TestNode
from rotation_node.conversions.warm_up import COMPILING
from scipy.spatial.transform import Rotation

# Starts processes or builds packages: not in the edit-test loop (-m "not slow").
pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parent.parent
EXECUTABLES = ('rotation_node', 'rotation_bag', 'rotation_scene')
SITE = os.path.join('lib', f'python{sys.version_info[0]}.{sys.version_info[1]}', 'site-packages')
#: Test oracles and study peers: never imported by the runtime package.
ORACLES = ('scipy', 'transforms3d', 'mpmath')

#: package.xml keys that exist (ROS 2 Jazzy packages, and rosdep keys checked in
#: rosdistro's rosdep/python.yaml). python3-mcap, python3-rosbags, python3-mpmath
#: and python3-zstandard do not exist.
KNOWN_KEYS = frozenset({
    'rclpy', 'rcl_interfaces', 'builtin_interfaces', 'rosidl_parser', 'std_msgs',
    'geometry_msgs', 'sensor_msgs', 'nav_msgs', 'diagnostic_msgs', 'tf2_msgs',
    'launch', 'launch_ros', 'ros2launch', 'ament_index_python', 'ament_flake8',
    'ament_pep257', 'ament_copyright',
    'python3-numpy', 'python3-numba', 'python3-yaml', 'python3-matplotlib', 'python3-scipy',
    'python3-transforms3d', 'python3-hypothesis', 'python3-pytest', 'python3-pytest-timeout',
    'mcap-ros2-support', 'python3-rosbags-pip',
})
#: The key of each Python distribution imported under another name; any other
#: import must be a ROS package of the same name. None: no rosdep key (pip only).
IMPORT_KEYS = {
    'numpy': 'python3-numpy', 'numba': 'python3-numba', 'yaml': 'python3-yaml',
    'matplotlib': 'python3-matplotlib', 'scipy': 'python3-scipy',
    'transforms3d': 'python3-transforms3d', 'hypothesis': 'python3-hypothesis',
    'pytest': 'python3-pytest', 'rosbags': 'python3-rosbags-pip',
    # mcap-ros2-support (pip) installs mcap, which requires zstandard and lz4.
    'mcap': 'mcap-ros2-support', 'mcap_ros2': 'mcap-ros2-support',
    # rosbags (pip) installs apsw, the SQLite binding its sqlite3 storage reads with.
    'apsw': 'python3-rosbags-pip',
    'zstandard': 'mcap-ros2-support', 'lz4': 'mcap-ros2-support',
    'mpmath': None,
    # Only rotation_node.bag.batch.convert_bags_on_dask imports it, for a caller who
    # brings a Dask cluster client (and so has it); not a dependency of the package.
    'distributed': None, 'dask': None,
    # Only rotation_bag export's Parquet output imports it (without it: one error line
    # asking for it); CSV needs nothing more. Not a dependency of the package.
    'pyarrow': None,
}


def _copy_sources(destination):
    """Copy the package's sources (no venv, builds, caches or outputs) to ``destination``."""
    shutil.copytree(ROOT, destination, ignore=shutil.ignore_patterns(
        '.git', '.venv', '.venv-jazzy', 'build', 'install', 'log', '__pycache__', '*.egg-info',
        '.pytest_cache', '.hypothesis', '*.mcap', '*.png', 'out'))
    return destination


@pytest.fixture(scope='module')
def oracle_blocker(tmp_path_factory):
    """Return a directory that, first on PYTHONPATH, makes every test oracle fail to import."""
    directory = tmp_path_factory.mktemp('no_oracles')
    for name in ORACLES:
        (directory / name).mkdir()
        (directory / name / '__init__.py').write_text(
            f'raise ImportError("{name} is a test oracle: the runtime package must not '
            f'import it")\n')
    return directory


def _pythonpath(*directories):
    return os.pathsep.join(str(d) for d in directories)


def _colcon(workspace, verb, *args, timeout=300):
    """Run ``colcon VERB`` in ``workspace`` (sources in src/); return the result."""
    colcon = os.path.join(os.path.dirname(sys.executable), 'colcon')
    if verb == 'test-result':
        bases = ['--test-result-base', 'build']
    else:
        bases = ['--base-paths', 'src', '--build-base', 'build', '--install-base', 'install']
    return subprocess.run([colcon, verb, *bases, *args], cwd=workspace, capture_output=True,
                          text=True, timeout=timeout)


@pytest.fixture(scope='module')
def colcon_workspace(tmp_path_factory):
    """Build a copy of the package with colcon; return the workspace (sources in src/)."""
    workspace = tmp_path_factory.mktemp('colcon_ws')
    _copy_sources(workspace / 'src' / 'rotation_node')
    result = _colcon(workspace, 'build', '--event-handlers', 'console_direct-')
    assert result.returncode == 0, result.stdout + result.stderr
    assert sorted(p.name for p in (workspace / 'install').iterdir() if p.is_dir()) == [
        'rotation_node'], 'colcon built more than the package (a nested package.xml?)'
    return workspace


@pytest.fixture(scope='module')
def colcon_install(colcon_workspace):
    """Return the install prefix of the package built by ``colcon build``."""
    return colcon_workspace / 'install' / 'rotation_node'


@pytest.fixture(scope='module')
def pip_install(tmp_path_factory):
    """Install a copy of the package with a non-editable ``pip install``; return its prefix."""
    sources = _copy_sources(tmp_path_factory.mktemp('pip_src') / 'rotation_node')
    prefix = tmp_path_factory.mktemp('pip_prefix')
    result = subprocess.run(
        # --ignore-installed: leave the environment's own (editable) rotation_node alone.
        [sys.executable, '-m', 'pip', 'install', '--quiet', '--no-deps', '--ignore-installed',
         '--prefix', str(prefix), str(sources)],
        capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stdout + result.stderr
    return prefix


def _run_installed(prefix, oracle_blocker, args, tmp_path, timeout=120):
    """Run an installed executable of ``prefix`` with its site-packages first, oracles blocked."""
    env = dict(os.environ, PYTHONPATH=_pythonpath(oracle_blocker, prefix / SITE))
    return subprocess.run([str(prefix / 'bin' / args[0]), *map(str, args[1:])], env=env,
                          cwd=tmp_path, capture_output=True, text=True, timeout=timeout)


def test_colcon_build_installs_what_ros2_run_and_ros2_launch_need(colcon_install):
    for exe in EXECUTABLES:
        path = colcon_install / 'lib' / 'rotation_node' / exe
        assert path.is_file() and os.access(path, os.X_OK), exe
    assert not (colcon_install / 'lib' / 'rotation_node' / 'rotation_bench').exists()
    share = colcon_install / 'share'
    assert (share / 'ament_index' / 'resource_index' / 'packages' / 'rotation_node').is_file()
    assert (share / 'rotation_node' / 'package.xml').is_file()
    assert (share / 'rotation_node' / 'config' / 'params.yaml').is_file()
    assert list((share / 'rotation_node' / 'config' / 'scenes').glob('*.yaml'))
    assert sorted(p.name for p in (share / 'rotation_node' / 'launch').iterdir()) == sorted(
        p.name for p in (ROOT / 'launch').glob('*.launch.py'))
    assert (colcon_install / SITE / 'rotation_node' / 'conversions' / '__init__.py').is_file()
    assert (colcon_install / SITE / 'rotation_node' / 'py.typed').is_file()   # PEP 561
    assert not (colcon_install / SITE / 'rotation_dev').exists()


#: A test module that colcon test must run with pytest and report: one pass, one failure.
PROBE_TESTS = """
def test_passing():
    assert 1 + 1 == 2


def test_deliberately_failing():
    assert 1 + 1 == 3
"""


def test_colcon_test_runs_pytest_and_test_result_reports_a_failing_test(colcon_workspace):
    probe = colcon_workspace / 'src' / 'rotation_node' / 'test' / 'test_colcon_probe.py'
    probe.write_text(PROBE_TESTS)
    try:
        # Only the probe (colcon passes --pytest-args on to pytest), not the whole suite again.
        tested = _colcon(colcon_workspace, 'test', '--return-code-on-test-failure',
                         '--pytest-args', str(probe.relative_to(probe.parents[1])))
    finally:
        probe.unlink()
    assert tested.returncode == 1, tested.stdout + tested.stderr
    assert 'Ran 0 tests' not in tested.stdout   # unittest, the fallback without pytest
    result = _colcon(colcon_workspace, 'test-result', '--verbose')
    assert result.returncode == 1, result.stdout + result.stderr
    assert 'Summary: 2 tests, 0 errors, 1 failure, 0 skipped' in result.stdout, result.stdout
    assert 'test_deliberately_failing' in result.stdout, result.stdout


def test_installed_launch_files_find_their_parameters_files(colcon_install):
    share = colcon_install / 'share' / 'rotation_node'
    for launch_file in sorted((share / 'launch').glob('*.launch.py')):
        description, _ = launch_description(launch_file, {'rotation_node': share})
        (node,) = launched_nodes(description)
        params_file = Path(node.parameters[0])
        assert params_file.is_file() and params_file.is_relative_to(share), launch_file.name


def _kernel_cache_files(colcon_install):
    """Return the numba cache index files of the installed package (or of NUMBA_CACHE_DIR)."""
    where = Path(os.environ.get('NUMBA_CACHE_DIR') or colcon_install / SITE / 'rotation_node')
    return sorted(where.rglob('*.nbi'))


def _run_installed_node(colcon_install, oracle_blocker, until_cached):
    """
    Start the installed node, convert Imu messages, Ctrl-C it; return (output, converted).

    ``converted`` is how many cache files existed when the first output arrived. With
    ``until_cached`` the messages go on until the kernels the node uses are compiled and
    cached (the cache files stop changing), before the Ctrl-C.
    """
    from sensor_msgs.msg import Imu
    from geometry_msgs.msg import Vector3Stamped
    env = {'PYTHONPATH': _pythonpath(oracle_blocker, colcon_install / SITE,
                                     *filter(None, [os.environ.get('PYTHONPATH')]))}
    exe = colcon_install / 'lib' / 'rotation_node' / 'rotation_node'
    with TestNode() as client, RosProcess([exe], env=env) as node:
        publisher = client.node.create_publisher(Imu, '/input', 10)
        euler = client.collect(Vector3Stamped, '/euler')
        ready = client.spin_until(lambda: client.node.count_subscribers('/input') > 0,
                                  timeout=180)
        if not ready:
            node.stop()
            pytest.fail(f'no subscription to /input within 180 s; the node said:\n{node.output}')
        msg = Imu()
        msg.orientation.w = 1.0

        def publish_until(condition, timeout):
            deadline = time.monotonic() + timeout
            while time.monotonic() < deadline and not condition():
                msg.header.stamp.nanosec = (msg.header.stamp.nanosec + 10_000_000) % 10**9
                publisher.publish(msg)
                client.spin_for(0.05)
            return condition()

        assert publish_until(lambda: euler, 60), 'no output within 60 s'
        cached_at_first_output = len(_kernel_cache_files(colcon_install))
        if until_cached:
            seen = [(), time.monotonic()]

            def settled():
                files = tuple(_kernel_cache_files(colcon_install))
                if files != seen[0]:
                    seen[:] = [files, time.monotonic()]
                return bool(files) and time.monotonic() - seen[1] > 5.0
            assert publish_until(settled, 300), 'the kernels were not cached within 300 s'
        assert node.stop() == 0, node.output
    return node.output, cached_at_first_output


def test_installed_node_starts_without_oracles_and_stops_on_ctrl_c(
        colcon_install, oracle_blocker):
    # The first start after colcon build converts at once (interpreted), compiles the
    # kernels it uses in the background, and says so while it does.
    first, cached = _run_installed_node(colcon_install, oracle_blocker, until_cached=True)
    assert cached == 0, 'the first output waited for compiled kernels'
    assert COMPILING in first, first
    assert re.search(r'\] \[rotation_node\]: \d+ kernels compiled in [0-9.]+ s and cached\n',
                     first), first
    # Every later start loads them from the cache.
    second, _ = _run_installed_node(colcon_install, oracle_blocker, until_cached=False)
    assert 'compil' not in second, second


def test_pip_install_holds_the_runtime_package_only(pip_install, oracle_blocker, tmp_path):
    site = pip_install / SITE
    assert sorted(p.name for p in site.iterdir() if not p.name.endswith('-info')) == [
        'rotation_node']
    assert sorted(p.name for p in (pip_install / 'bin').iterdir()) == sorted(EXECUTABLES)
    # The installed copy is what runs, not the checkout's editable install.
    result = _run_installed(pip_install, oracle_blocker, ['rotation_bag', '--help'], tmp_path)
    code = 'import rotation_node; print(rotation_node.__file__)'
    where = subprocess.run([sys.executable, '-c', code], cwd=tmp_path, text=True,
                           capture_output=True, timeout=60,
                           env=dict(os.environ, PYTHONPATH=_pythonpath(oracle_blocker, site)))
    assert where.stdout.startswith(str(site)), where.stdout + where.stderr
    assert result.returncode == 0, result.stderr


@pytest.mark.parametrize('exe', EXECUTABLES)
def test_pip_installed_executable_prints_its_usage(pip_install, oracle_blocker, tmp_path, exe):
    result = _run_installed(pip_install, oracle_blocker, [exe, '--help'], tmp_path)
    assert result.returncode == 0, result.stdout + result.stderr
    assert result.stdout.startswith(f'usage: {exe} '), result.stdout


def test_pip_installed_scene_and_convert_give_roll_pitch_yaw(pip_install, oracle_blocker,
                                                             tmp_path):
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    config = pip_install / 'share' / 'rotation_node' / 'config'
    scene = _run_installed(pip_install, oracle_blocker, [
        'rotation_scene', config / 'scenes' / 'constant_rate_spin.yaml', 'scene.mcap'],
        tmp_path)
    assert scene.returncode == 0, scene.stdout + scene.stderr
    converted = _run_installed(pip_install, oracle_blocker, [
        'rotation_bag', 'convert', 'scene.mcap', 'converted.mcap',
        '--params', config / 'params.yaml'], tmp_path)
    assert converted.returncode == 0, converted.stdout + converted.stderr

    imu, euler = {}, {}
    with open(tmp_path / 'converted.mcap', 'rb') as stream:
        records = list(make_reader(stream, decoder_factories=[DecoderFactory()])
                       .iter_decoded_messages(topics=['/imu', '/imu/euler']))
    for _, channel, _, msg in records:
        stamp = msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec
        if channel.topic == '/imu':
            q = msg.orientation
            imu[stamp] = (q.x, q.y, q.z, q.w)
        else:
            euler[stamp] = (msg.vector.x, msg.vector.y, msg.vector.z)
    assert len(imu) == 501 and sorted(euler) == sorted(imu)
    stamps = sorted(imu)
    expected = Rotation.from_quat([imu[s] for s in stamps]).as_euler('xyz')
    got = np.array([euler[s] for s in stamps])
    difference = np.angle(np.exp(1j * (got - expected)))   # modulo 2 pi
    assert np.abs(difference).max() < 1e-12


def _imports(paths):
    """``{top-level module: first file importing it}`` of absolute imports in ``paths``."""
    found = {}
    for path in paths:
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0:
                names = [node.module]
            else:
                continue
            for name in names:
                top = name.split('.')[0]
                if top not in sys.stdlib_module_names:
                    found.setdefault(top, path.relative_to(ROOT))
    return found


def _package_xml_keys(*tags):
    root = ElementTree.parse(ROOT / 'package.xml').getroot()
    return {e.text for tag in (*tags, 'depend') for e in root.findall(tag)}


def _missing_keys(imports, declared, local):
    """Return the imports whose key is not declared: ``{module: (key, file)}``."""
    missing = {}
    for module, path in imports.items():
        if module in local:
            continue
        key = IMPORT_KEYS.get(module, module)
        if key is not None and key not in declared:
            missing[module] = (key, str(path))
    return missing


def test_package_xml_is_format_3_ament_python():
    root = ElementTree.parse(ROOT / 'package.xml').getroot()
    assert root.get('format') == '3'
    assert root.findtext('name') == 'rotation_node'
    assert root.findtext('license') == 'Apache-2.0'
    assert (ROOT / 'LICENSE').read_text().split()[:4] == ['Apache', 'License', 'Version',
                                                          '2.0,']
    assert root.find('export').findtext('build_type') == 'ament_python'


def test_package_xml_names_only_keys_that_exist():
    root = ElementTree.parse(ROOT / 'package.xml').getroot()
    keys = [e.text for e in root.iter() if e.tag.endswith('depend')]
    assert keys and set(keys) <= KNOWN_KEYS, sorted(set(keys) - KNOWN_KEYS)


def test_package_xml_declares_every_runtime_import():
    runtime = [*(ROOT / 'rotation_node').rglob('*.py'), *(ROOT / 'launch').glob('*.py')]
    imports = _imports(runtime)
    assert 'rclpy' in imports and 'numpy' in imports   # the scan sees the imports
    assert not set(ORACLES) & set(imports), 'the runtime package imports a test oracle'
    assert _missing_keys(imports, _package_xml_keys('exec_depend'), {'rotation_node'}) == {}


def test_package_xml_declares_every_test_import():
    imports = _imports([*(ROOT / 'test').glob('*.py'), *(ROOT / 'rotation_dev').rglob('*.py')])
    local = {'rotation_node', 'rotation_dev', 'launch_stubs',
             *(p.stem for p in (ROOT / 'test').glob('*.py'))}
    declared = _package_xml_keys('exec_depend', 'test_depend')
    assert _missing_keys(imports, declared, local) == {}


#: What setup.py passes to ``setuptools.setup`` (colcon reads its test requirements the same way).
SETUP_REQUIREMENTS = """
import json
import runpy
import setuptools
setuptools.setup = lambda **arguments: print(json.dumps(
    [arguments.get('install_requires', []), arguments.get('extras_require', {})]))
runpy.run_path('setup.py')
"""
#: The rosdep key of each Python distribution whose versions setup.py bounds.
VERSION_KEYS = {'numpy': 'python3-numpy', 'numba': 'python3-numba', 'PyYAML': 'python3-yaml',
                'matplotlib': 'python3-matplotlib', 'scipy': 'python3-scipy'}


@functools.cache   # one process start for the three tests that read them
def _setup_requirements():
    """Return setup.py's ``(install_requires, extras_require)``."""
    result = subprocess.run([sys.executable, '-c', SETUP_REQUIREMENTS], cwd=ROOT,
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    return tuple(json.loads(result.stdout))


def _version(text):
    return tuple(int(part) for part in text.strip().split('.'))


def _bounds(requirement):
    """``'numpy >= 1.26.4, < 2.5'`` -> ``('numpy', {'>=': (1, 26, 4), '<': (2, 5)})``."""
    name, specifiers = re.fullmatch(r'([A-Za-z0-9_.-]+)\s*(.*)', requirement).groups()
    bounds = {}
    for specifier in filter(None, (s.strip() for s in specifiers.split(','))):
        operator, version = re.fullmatch(r'(>=|<)\s*([0-9.]+)', specifier).groups()
        bounds[operator] = _version(version)
    return name, bounds


def _pins(path):
    """Return ``{distribution: version}`` of the ``name==version`` lines of ``path``."""
    pins = {}
    for line in path.read_text().splitlines():
        match = re.fullmatch(r'([A-Za-z0-9_.-]+)(\[[^]]*\])?==([0-9.]+)', line.strip())
        if match:
            pins[match.group(1).lower()] = _version(match.group(3))
    return pins


def test_setup_py_declares_pytest_as_the_test_requirement_colcon_test_looks_for():
    # colcon test runs pytest for a package whose tests_require or extras_require['test']
    # names it, and `python -m unittest` (no test found, success) for any other.
    _, extras = _setup_requirements()
    assert 'pytest' in [_bounds(r)[0] for r in extras['test']]


def test_supported_versions_run_from_the_jazzy_platform_to_the_pins():
    install, extras = _setup_requirements()
    ranges = dict(_bounds(r) for r in install + extras['test'])
    jazzy = _pins(ROOT / 'tools' / 'jazzy_platform.txt')
    pinned = _pins(ROOT / 'requirements.txt')
    # numba's own llvmlite, and the newest pyarrow that loads with the platform's numpy
    assert set(jazzy) - {'llvmlite', 'pyarrow'} == {name.lower() for name in VERSION_KEYS}
    for name in VERSION_KEYS:
        bounds = ranges[name]
        assert bounds['>='] == jazzy[name.lower()], (name, bounds)   # the lower end is Jazzy's
        assert bounds['>='] <= pinned[name.lower()] < bounds['<'], (name, bounds)


def test_package_xml_bounds_the_versions_as_setup_py_does():
    install, extras = _setup_requirements()
    ranges = dict(_bounds(r) for r in install + extras['test'])
    root = ElementTree.parse(ROOT / 'package.xml').getroot()
    declared = {e.text: e for e in root if e.tag.endswith('depend')}
    for name, key in VERSION_KEYS.items():
        attributes = {operator: _version(declared[key].get(attribute, '0'))
                      for operator, attribute in (('>=', 'version_gte'), ('<', 'version_lt'))}
        assert attributes == ranges[name], key


IMPORT_EVERY_MODULE = """
import importlib
import pkgutil
try:
    import scipy  # noqa: F401
except ImportError:
    pass
else:
    raise SystemExit('the oracle blocker does not block scipy')
import rotation_node
names = [m.name for m in pkgutil.walk_packages(rotation_node.__path__, 'rotation_node.')]
for name in names:
    importlib.import_module(name)
print(len(names), 'modules imported')
"""


def test_runtime_modules_import_without_the_oracles(oracle_blocker):
    result = subprocess.run([sys.executable, '-c', IMPORT_EVERY_MODULE], capture_output=True,
                            text=True, timeout=120, cwd=oracle_blocker,
                            env=dict(os.environ, PYTHONPATH=_pythonpath(oracle_blocker)))
    assert result.returncode == 0, result.stderr
    assert int(result.stdout.split()[0]) > 30, result.stdout
