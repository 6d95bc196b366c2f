"""
The layering of ``rotation_node``: imports only downward, no circles.

``LAYERS`` is the one declaration of the layer order (docs/ARCHITECTURE.md draws it).
Every module's imports are read from its source with ``ast`` (function-level
imports and ``TYPE_CHECKING`` blocks included, relative imports resolved), and
a module may import:

- any module of a lower layer,
- a module of its own group (the modules of one group may use each other, as
  long as they form no circle),

and nothing else: not a higher layer, not a sibling group of its own layer
(the groups of one layer stand side by side, e.g. reading and writing bags).
A module belongs to the group of the longest name in ``LAYERS`` that it is or
lies under, so that a new module of a package is placed with it.
"""
import ast
import functools
import os

import pytest

PACKAGE = 'rotation_node'
ROOT = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), PACKAGE)

# Bottom first: (layer, groups), a group being the module and package names it holds.
LAYERS = (
    ('foundation', (
        ('rotation_node', 'rotation_node.type_aliases', 'rotation_node.errors'),
    )),
    # The numerical library: numpy + numba, no ROS (LIBRARY below).
    ('conversions', (('rotation_node.conversions',),)),
    ('kinematics', (('rotation_node.kinematics', 'rotation_node._arrays'),)),
    ('library', (
        ('rotation_node.comparison',),
        ('rotation_node.covariance',),
        ('rotation_node.frames',),
        ('rotation_node.mounting',),
    )),
    # Compiles every kernel of conversions and kinematics (run.sh set-up, node start).
    ('warm-up', (('rotation_node.conversions.warm_up',),)),
    # Helpers with no knowledge of messages: YAML as rcl types it, value checks,
    # the command-line pieces (stop signal, progress, topic arguments).
    ('support', (
        ('rotation_node.ros_yaml',),
        ('rotation_node.validation',),
        ('rotation_node.command_line',),
        # The private rclpy APIs still needed, with the rclpy versions checked.
        ('rotation_node.rclpy_private',),
    )),
    # Samples of one stream as arrays: what the block codec decodes and the pipeline converts.
    ('sample blocks', (('rotation_node.sample_block',),)),
    # The ROS 2 wire format: CDR, message types, QoS as rosbag2 stores it, stamps.
    ('wire', (('rotation_node.wire',),)),
    # Bags as files, in terms of records; reading and writing side by side.
    ('bag records', (('rotation_node.bag.records', 'rotation_node.bag.mcap_layout',
                      'rotation_node.bag.metadata_yaml'),)),
    ('bag files', (
        ('rotation_node.bag.reading',),
        ('rotation_node.bag.writing',),
    )),
    ('tf', (('rotation_node.tf_buffer',),)),
    # What a message type is: the registry.
    ('registry', (('rotation_node.registry',),)),
    # The stateful sample streams of input types (tf), built on the registry's Sample.
    ('stateful inputs', (('rotation_node.tf_input',),)),
    ('parameters', (('rotation_node.parameters', 'rotation_node.static_mounting'),)),
    # One input stream -> named values -> outputs, for the node and for convert.
    ('pipeline', (('rotation_node.pipeline',),)),
    # The programs, side by side: none imports another.
    ('applications', (
        ('rotation_node.node',),
        ('rotation_node.bag',),
        ('rotation_node.scene',),
        ('rotation_node.markdown_tables',),
    )),
    # The console scripts' entry points import the programs by name (importlib).
    ('entry points', (('rotation_node.command_line.console',),)),
)

# Known upward imports (none: test_known_violations_still_exist keeps this list honest).
KNOWN_VIOLATIONS: set = set()

# The numerical library imports no ROS package (it runs without ROS).
LIBRARY = ('rotation_node.conversions', 'rotation_node.kinematics', 'rotation_node._arrays',
           'rotation_node.comparison', 'rotation_node.covariance', 'rotation_node.frames',
           'rotation_node.mounting')
ROS_PACKAGES = ('rclpy', 'rosidl_parser', 'rosidl_runtime_py', 'rosbags', 'mcap_ros2',
                'builtin_interfaces', 'rcl_interfaces', 'launch', 'launch_ros',
                'ament_index_python')

# Only the programs run a node: below them nothing imports rclpy's node machinery.
NODE_MACHINERY = ('rclpy', 'rclpy.node', 'rclpy.executors', 'rclpy.context',
                  'rclpy.subscription', 'rclpy.publisher')

# rclpy's private APIs (they can change in any release) are used in one module only.
RCLPY_PRIVATE = ('rclpy.impl', 'rclpy._rclpy_pybind11')
PRIVATE_API_MODULE = 'rotation_node.rclpy_private'
KNOWN_PRIVATE_API_USERS: set = set()


def _module_files():
    """Return ``{module name: source path}`` of every module of the package."""
    files = {}
    for directory, subdirectories, names in os.walk(ROOT):
        subdirectories[:] = sorted(d for d in subdirectories if d != '__pycache__')
        for name in names:
            if name.endswith('.py'):
                path = os.path.join(directory, name)
                parts = os.path.relpath(path[:-3], os.path.dirname(ROOT)).split(os.sep)
                if parts[-1] == '__init__':
                    parts.pop()
                files['.'.join(parts)] = path
    return files


MODULES = _module_files()


@functools.lru_cache(maxsize=None)
def _parsed(path):
    with open(path, encoding='utf-8') as source:
        return ast.parse(source.read(), path)


def _imported_names(module, path):
    """Return every name ``module`` imports (absolute, dotted), with the line of each."""
    tree = _parsed(str(path))
    package = module if path.endswith('__init__.py') else module.rpartition('.')[0]
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found.extend((alias.name, node.lineno) for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split('.')[:len(package.split('.')) - (node.level - 1)]
                source = '.'.join(base + ([node.module] if node.module else []))
            else:
                source = node.module
            for alias in node.names:
                # `from package import module` imports the module.
                name = f'{source}.{alias.name}'
                found.append((name if name in MODULES else source, node.lineno))
    return found


def _internal_imports():
    """Return ``{module: {imported module of the package: first line}}``."""
    graph = {}
    for module, path in MODULES.items():
        edges = {}
        for name, line in _imported_names(module, path):
            while name not in MODULES and '.' in name and name.startswith(PACKAGE + '.'):
                name = name.rpartition('.')[0]     # an attribute of a module
            if name in MODULES and name != module:
                edges.setdefault(name, line)
        graph[module] = edges
    return graph


GRAPH = _internal_imports()


def _place(module):
    """``(layer index, group index)`` of a module, or None when LAYERS does not place it."""
    best = None
    for layer_index, (_, groups) in enumerate(LAYERS):
        for group_index, group in enumerate(groups):
            for name in group:
                # The package itself is its __init__ only, not a prefix of every module.
                if module == name or (name != PACKAGE and module.startswith(name + '.')):
                    if best is None or len(name) > len(best[0]):
                        best = (name, layer_index, group_index)
    return None if best is None else best[1:]


def _upward_imports():
    found = set()
    for module, edges in GRAPH.items():
        if _place(module) is None:
            continue    # test_every_module_has_a_layer names it
        layer, group = _place(module)
        for target in edges:
            if _place(target) is None:
                continue
            target_layer, target_group = _place(target)
            if target_layer > layer or (target_layer == layer and target_group != group):
                found.add((module, target))
    return found


def _import_circles(graph):
    """Strongly connected components of more than one module (Tarjan's algorithm)."""
    index, low, stack, on_stack, circles = {}, {}, [], set(), []

    def visit(module):
        index[module] = low[module] = len(index)
        stack.append(module)
        on_stack.add(module)
        for target in graph[module]:
            if target not in index:
                visit(target)
                low[module] = min(low[module], low[target])
            elif target in on_stack:
                low[module] = min(low[module], index[target])
        if low[module] == index[module]:
            component = []
            while True:
                member = stack.pop()
                on_stack.discard(member)
                component.append(member)
                if member == module:
                    break
            if len(component) > 1:
                circles.append(sorted(component))

    for module in sorted(graph):
        if module not in index:
            visit(module)
    return circles


def test_modules_found():
    # The walk finds the package, its subpackages and the modules the layers name.
    assert {'rotation_node', 'rotation_node.conversions', 'rotation_node.wire.cdr',
            'rotation_node.bag.reading.reader', 'rotation_node.bag.cli'} <= set(MODULES)
    assert 'rotation_node.conversions._runtime' in GRAPH['rotation_node.conversions']


def test_relative_and_function_level_imports_are_read(tmp_path):
    source = tmp_path / 'example.py'
    source.write_text('from . import errors\n'
                      'from .wire.cdr import fixed_layout_codec\n'
                      'def f():\n'
                      '    from rotation_node.bag.reading import reader\n'
                      '    import rclpy.node\n')
    names = [name for name, _ in _imported_names('rotation_node.example', str(source))]
    assert names == ['rotation_node.errors', 'rotation_node.wire.cdr',
                     'rotation_node.bag.reading.reader', 'rclpy.node']


@pytest.mark.parametrize('module', sorted(MODULES))
def test_every_module_has_a_layer(module):
    assert _place(module) is not None, (
        f'{module} is in no layer of LAYERS: add it to the group it belongs to')


def test_imports_only_downward():
    upward = _upward_imports() - KNOWN_VIOLATIONS
    lines = [f'{module} (line {GRAPH[module][target]}) imports {target} '
             f'({LAYERS[_place(target)[0]][0]} over {LAYERS[_place(module)[0]][0]})'
             for module, target in sorted(upward)]
    assert not lines, 'imports against the layer order:\n' + '\n'.join(lines)


def test_known_violations_still_exist():
    gone = KNOWN_VIOLATIONS - _upward_imports()
    assert not gone, f'fixed, remove from KNOWN_VIOLATIONS: {sorted(gone)}'


def test_no_import_circles():
    graph = {module: {target: line for target, line in edges.items()
                      if (module, target) not in KNOWN_VIOLATIONS}
             for module, edges in GRAPH.items()}
    assert _import_circles(graph) == []


def test_circles_are_found():
    # The check sees a circle of three modules and the modules that only lead into it.
    graph = {'a': {'b': 1}, 'b': {'c': 1}, 'c': {'a': 1}, 'd': {'a': 1}}
    assert _import_circles(graph) == [['a', 'b', 'c']]


@pytest.mark.parametrize('module', sorted(MODULES))
def test_no_module_getattr(module):
    names = {node.name for node in _parsed(MODULES[module]).body
             if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef))}
    assert not names & {'__getattr__', '__dir__'}, (
        f'{module} defines a module __getattr__: import names from where they are defined')


def _under(module, names):
    return any(module == name or module.startswith(name + '.') for name in names)


@pytest.mark.parametrize('module', sorted(m for m in MODULES if _under(m, LIBRARY)))
def test_library_imports_no_ros(module):
    ros = sorted({name for name, _ in _imported_names(module, MODULES[module])
                  if _under(name, ROS_PACKAGES) or name.split('.')[0].endswith('_msgs')})
    assert ros == []


@pytest.mark.parametrize('module', sorted(
    m for m in MODULES if m != PRIVATE_API_MODULE and _place(m) is not None
    and _place(m)[0] < [name for name, _ in LAYERS].index('applications')))
def test_no_node_machinery_below_the_programs(module):
    # (The private-API module wraps parts of rclpy's subscriptions for the node.)
    used = sorted({name for name, _ in _imported_names(module, MODULES[module])
                   if name in NODE_MACHINERY})
    assert used == []


def _private_api_users():
    return {module for module, path in MODULES.items()
            if module != PRIVATE_API_MODULE
            and any(_under(name, RCLPY_PRIVATE) for name, _ in _imported_names(module, path))}


def test_private_rclpy_apis_in_one_module():
    assert _private_api_users() - KNOWN_PRIVATE_API_USERS == set(), (
        f'import private rclpy APIs from {PRIVATE_API_MODULE} only')
    assert KNOWN_PRIVATE_API_USERS <= _private_api_users(), (
        'fixed, remove from KNOWN_PRIVATE_API_USERS: '
        f'{sorted(KNOWN_PRIVATE_API_USERS - _private_api_users())}')
