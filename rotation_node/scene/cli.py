"""
``rotation_scene SCENE.yaml OUT [--seed N] [--force]``: simulate a scene file into a bag.

Any failure prints one line, ``rotation_scene: error: ...``, exits 1 and leaves no output;
Ctrl-C or SIGTERM one line, status 130 or 143, no output.
"""
import argparse
import sys
from typing import Optional, Sequence

from rotation_node.command_line.stop_signal import exit_status, signal_name, StopSignal
from rotation_node.errors import RotationNodeError


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
                    'and /truth/angular_velocity (and, when the scene has a reference, a second '
                    'stream and OUT.truth.json).')
    parser.add_argument('scene', help='scene file (YAML), e.g. config/scenes/coning.yaml')
    parser.add_argument('output', help='bag to write: a rosbag2 directory, or a single MCAP '
                                       'file if it ends in .mcap, e.g. coning.mcap')
    parser.add_argument('--seed', type=_seed, default=0,
                        help="seed of the effects' random draws (default 0); the same scene "
                             'and seed give a byte-identical bag')
    parser.add_argument('--force', action='store_true', help='replace the output if it exists')
    return parser


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Run ``rotation_scene``; return the exit status."""
    args = build_parser().parse_args(argv)
    with StopSignal():   # a signal stops the simulation where it checks
        try:
            # Imported here, where a signal only sets the stop flag (see bag.stop_signal).
            from rotation_node.bag.writing.part_output import BagOutput

            from .simulator import write_scene_bag
            from .spec import load_scene

            # Checked again when the bag is opened; here it saves loading the scene for nothing.
            BagOutput.check_absent(args.output, overwrite=args.force)
            scene = load_scene(args.scene)
            n, published = write_scene_bag(scene, args.output, seed=args.seed,
                                           overwrite=args.force)
        except (RotationNodeError, OSError) as exc:
            one_line = ' '.join(str(exc).split())
            print(f'rotation_scene: error: {one_line}', file=sys.stderr)
            return 1
        except KeyboardInterrupt as interrupt:
            print(f'rotation_scene: interrupted ({signal_name(interrupt)})', file=sys.stderr)
            return exit_status(interrupt)
        effects = ', '.join(scene.effects) or 'none'
        print(f'{args.output}: {n} samples over {scene.duration:g} s at {scene.rate:g} Hz, '
              f'motion {scene.motion.type}, effects {effects}; '
              f'{published} sensor messages on {scene.topic}, {n} on each truth topic')
        if scene.reference is not None:
            from .reference import reference_index_range, truth_path
            first, stop = reference_index_range(scene)
            print(f'{args.output}: reference stream: {stop - first} messages on '
                  f'{scene.reference.topic} at {scene.reference.rate:g} Hz; its truth in '
                  f'{truth_path(args.output)}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
