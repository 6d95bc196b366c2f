"""
Scene simulator: scene files -> truth and sensor streams -> MCAP test bags.

``load_scene(path)`` validates a YAML scene (:mod:`.spec`), ``simulate(scene, seed)`` returns
the truth and sensor arrays (:mod:`.motions`, :mod:`.effects`), ``write_bag(simulation,
path)`` writes them as a ROS 2 bag, ``write_scene_bag`` does both streaming
(:mod:`.simulator`). The command line is ``rotation_scene`` (:mod:`.cli`).
"""
from .simulator import simulate, write_bag, write_scene_bag
from .spec import load_scene

__all__ = ['load_scene', 'simulate', 'write_bag', 'write_scene_bag']
