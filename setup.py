"""ament_python package rotation_node: rotation conversions on ROS 2 topics and bags."""
from glob import glob

from setuptools import find_packages, setup

package_name = 'rotation_node'

# The versions supported, from ROS 2 Jazzy's platform (Ubuntu 24.04's packages, the pins of
# tools/jazzy_platform.txt, tested by tools/test_jazzy_platform.sh) up to the series of the
# pins of requirements.txt (the development venv, tested by ./run.sh test). package.xml
# names the same bounds for rosdep (test/test_package.py checks that all of these agree).
install_requires = [
    'setuptools',
    'numpy >= 1.26.4, < 2.5',
    'numba >= 0.59.0, < 0.69',
    'PyYAML >= 6.0.1, < 7',
    'matplotlib >= 3.6.3, < 3.12',
]
# `colcon test` runs the tests with pytest because pytest is a test requirement here
# (otherwise it runs `python -m unittest`, which finds none); `pip install .[test]`.
tests_require = [
    'pytest',
    'scipy >= 1.11.4, < 1.18',
]

setup(
    name=package_name,
    version='0.1.0',
    # The runtime package only: rotation_dev (study, demo, hard cases) stays in the checkout.
    packages=find_packages(include=['rotation_node', 'rotation_node.*']),
    package_data={package_name: ['py.typed']},
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config', glob('config/*.yaml')),
        ('share/' + package_name + '/launch', glob('launch/*.launch.py')),
        ('share/' + package_name + '/config/scenes', glob('config/scenes/*.yaml')),
    ],
    install_requires=install_requires,
    extras_require={'test': tests_require},
    zip_safe=False,
    maintainer='rotation_node developers',
    maintainer_email='dev@rotation-node.invalid',
    description='Exact, fast rotation and angular-velocity conversions for ROS 2 topics and '
                'MCAP bags.',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'rotation_node = rotation_node.command_line.console:rotation_node',
            'rotation_bag = rotation_node.command_line.console:rotation_bag',
            'rotation_scene = rotation_node.command_line.console:rotation_scene',
        ],
    },
)
