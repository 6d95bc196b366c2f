"""
``rotation_scene SCENE.yaml OUT.mcap [--seed N] [--force]``: simulate a scene file into a bag.

On bad input (scene file, seed, existing output) it prints one line,
``rotation_scene: error: ...``, exits with status 1 and leaves no output file.
"""
import argparse
import os
import sys
from typing import Optional, Sequence

from rotation_node.errors import BagError, SceneError

from .simulator import simulate, write_bag
from .spec import load_scene


def _seed(text):
    try:
        seed = int(text)
    except ValueError:
        seed = -1
    if seed < 0:
        raise argparse.ArgumentTypeError(f'expected a non-negative integer, got {text!r}')
    return seed


def build_parser() -> argparse.ArgumentParser:
    """Return the command-line parser of ``rotation_scene``."""
    parser = argparse.ArgumentParser(
        prog='rotation_scene',
        description='Simulate a scene file (motion + sensor effects) into a ROS 2 MCAP bag '
                    'holding the sensor_msgs/Imu stream and the truth on /truth/orientation '
                    'and /truth/angular_velocity.')
    parser.add_argument('scene', help='scene file (YAML), e.g. config/scenes/coning.yaml')
    parser.add_argument('output', help='bag to write, e.g. coning.mcap')
    parser.add_argument('--seed', type=_seed, default=0,
                        help='seed of the effects\' random draws (default 0); the same scene '
                             'and seed give a byte-identical bag')
    parser.add_argument('--force', action='store_true', help='overwrite OUT.mcap if it exists')
    return parser


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Run ``rotation_scene``; return the exit status."""
    args = build_parser().parse_args(argv)
    try:
        # Checked again when the bag is opened; here it saves simulating for nothing.
        if os.path.lexists(args.output) and not args.force:
            raise BagError(f'output {args.output} already exists (use --force to overwrite it)')
        scene = load_scene(args.scene)
        simulation = simulate(scene, args.seed)
        write_bag(simulation, args.output, overwrite=args.force)
    except (SceneError, BagError) as exc:
        one_line = ' '.join(str(exc).split())
        print(f'rotation_scene: error: {one_line}', file=sys.stderr)
        return 1
    n = len(simulation.time)
    published = int(simulation.sensor.published.sum())
    effects = ', '.join(scene.effects) or 'none'
    print(f'{args.output}: {n} samples over {scene.duration:g} s at {scene.rate:g} Hz, '
          f'motion {scene.motion.type}, effects {effects}; '
          f'{published} sensor messages on {scene.topic}, {n} on each truth topic')
    return 0


if __name__ == '__main__':
    sys.exit(main())
