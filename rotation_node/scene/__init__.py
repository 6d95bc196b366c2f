"""
Scene simulator: scene files -> truth and sensor streams -> MCAP test bags.

``load_scene(path)`` validates a YAML scene (:mod:`.spec`), ``simulate(scene,
seed)`` returns the truth and sensor arrays (:mod:`.motions`, :mod:`.effects`),
``write_bag(simulation, path)`` writes them as a ROS 2 bag (:mod:`.simulator`).
The command line is ``rotation_scene`` (:mod:`.cli`).
"""
from .effects import SensorStream
from .simulator import (
    sample_stamps_ns, simulate, simulate_blocks, Simulation, write_bag, write_scene_bag)
from .spec import load_scene, Scene, scene_from_dict

__all__ = ['Scene', 'SensorStream', 'Simulation', 'load_scene', 'sample_stamps_ns',
           'scene_from_dict', 'simulate', 'simulate_blocks', 'write_bag', 'write_scene_bag']
