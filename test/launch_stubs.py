"""
Load the package's launch files without ROS: recording stand-ins for the launch API.

``launch`` and ``launch_ros`` are not on PyPI, so ``ros2 launch`` cannot run here.
:func:`launch_description` runs a launch file's ``generate_launch_description()``
with stand-ins for the parts of ``launch``, ``launch_ros`` and ``ament_index_python``
the package's launch files use; each stand-in takes the same arguments as the real
class (a keyword the real one does not accept is a ``TypeError`` here too) and
records them. :func:`launched_nodes` then evaluates the description for given
launch arguments as ``ros2 launch`` does: declared defaults, overridden by the
arguments, ``OpaqueFunction`` s called with a context holding them.
"""
import runpy
import sys
import types
from unittest import mock


class LaunchDescription:
    """``launch.LaunchDescription(initial_entities=None, *, deprecated_reason=None)``."""

    def __init__(self, initial_entities=None, *, deprecated_reason=None):
        self.entities = list(initial_entities or [])


class DeclareLaunchArgument:
    """``launch.actions.DeclareLaunchArgument(name, *, default_value, description, choices)``."""

    def __init__(self, name, *, default_value=None, description=None, choices=None):
        self.name, self.default_value = name, default_value
        self.description, self.choices = description, choices


class OpaqueFunction:
    """``launch.actions.OpaqueFunction(*, function, args=None, kwargs=None)``."""

    def __init__(self, *, function, args=None, kwargs=None):
        self.function, self.args, self.kwargs = function, args or [], kwargs or {}


class LaunchConfiguration:
    """``launch.substitutions.LaunchConfiguration(variable_name, *, default=None)``."""

    def __init__(self, variable_name, *, default=None):
        self.variable_name, self.default = variable_name, default


class Node:
    """``launch_ros.actions.Node(*, executable, package, name, namespace, ...)``."""

    def __init__(self, *, executable, package=None, name=None, namespace=None, exec_name=None,
                 parameters=None, remappings=None, ros_arguments=None, arguments=None,
                 output=None, emulate_tty=None, respawn=None, respawn_delay=None):
        self.executable, self.package, self.name = executable, package, name
        self.namespace, self.parameters = namespace, list(parameters or [])
        self.remappings, self.arguments = list(remappings or []), list(arguments or [])


class LaunchContext:
    """What an ``OpaqueFunction`` reads: ``launch_configurations``, ``{name: str}``."""

    def __init__(self, launch_configurations):
        self.launch_configurations = dict(launch_configurations)


def _modules(share_directories):
    """Return the stand-in modules; ``get_package_share_directory`` reads ``share_directories``."""
    def get_package_share_directory(package_name):
        if package_name not in share_directories:
            raise LookupError(f"package '{package_name}' not found")  # PackageNotFoundError
        return str(share_directories[package_name])

    def module(name, **attributes):
        stub = types.ModuleType(name)
        stub.__dict__.update(attributes)
        return stub

    return {
        'launch': module('launch', LaunchDescription=LaunchDescription),
        'launch.actions': module('launch.actions', DeclareLaunchArgument=DeclareLaunchArgument,
                                 OpaqueFunction=OpaqueFunction),
        'launch.substitutions': module('launch.substitutions',
                                       LaunchConfiguration=LaunchConfiguration),
        'launch_ros': module('launch_ros'),
        'launch_ros.actions': module('launch_ros.actions', Node=Node),
        'ament_index_python': module('ament_index_python'),
        'ament_index_python.packages': module(
            'ament_index_python.packages',
            get_package_share_directory=get_package_share_directory),
    }


def launch_description(path, share_directories):
    """
    Load a launch file with the stand-ins and return the description it generates.

    Parameters
    ----------
    path : str or os.PathLike
        The launch file.
    share_directories : dict
        ``{package: share directory}`` that ``get_package_share_directory`` returns.

    Returns
    -------
    (LaunchDescription, dict)
        The description and the launch file's module namespace.

    """
    with mock.patch.dict(sys.modules, _modules(share_directories)):
        namespace = runpy.run_path(str(path))
        return namespace['generate_launch_description'](), namespace


def declared_arguments(description):
    """``{name: DeclareLaunchArgument}`` of a launch description, in declaration order."""
    return {entity.name: entity for entity in description.entities
            if isinstance(entity, DeclareLaunchArgument)}


def launched_nodes(description, arguments=None):
    """
    Return the ``Node`` actions ``ros2 launch`` would start with the given arguments.

    Raises
    ------
    KeyError
        An argument the description does not declare.

    """
    declared = declared_arguments(description)
    configurations = {name: argument.default_value for name, argument in declared.items()}
    for name, value in (arguments or {}).items():
        if name not in declared:
            raise KeyError(f'launch argument {name!r} is not declared')
        configurations[name] = value
    nodes = []
    for entity in description.entities:
        if isinstance(entity, OpaqueFunction):
            nodes.extend(entity.function(LaunchContext(configurations), *entity.args,
                                         **entity.kwargs) or [])
        elif isinstance(entity, Node):
            nodes.append(entity)
    return nodes
