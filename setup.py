"""ament_python package rotation_node: rotation conversions on ROS 2 topics and bags."""
from glob import glob

from setuptools import find_packages, setup

package_name = 'rotation_node'

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
    install_requires=['setuptools'],
    zip_safe=False,
    maintainer='rotation_node developers',
    maintainer_email='dev@rotation-node.invalid',
    description='Exact, fast rotation and angular-velocity conversions for ROS 2 topics and '
                'MCAP bags.',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'rotation_node = rotation_node.console:rotation_node',
            'rotation_bag = rotation_node.console:rotation_bag',
            'rotation_scene = rotation_node.console:rotation_scene',
        ],
    },
)
