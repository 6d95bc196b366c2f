"""
The README's tables of input types, outputs and parameters, rendered from the code.

From the registry and the parameter table; a test keeps the README equal to them. Print them
with ``python -m rotation_node.markdown_tables``.
"""
from rotation_node import registry
from rotation_node.parameters import PARAMETERS


INPUT_NOTES = {
    'imu': 'orientation unknown when `orientation_covariance[0] == -1` or the quaternion is '
           '(0, 0, 0, 0); angular velocity by finite difference when '
           '`angular_velocity_covariance[0] == -1`',
    'euler': 'x, y, z = first, second, third angle of `euler.sequence` (degrees with '
             '`euler.degrees`)',
    'rotation_vector': 'axis times angle (rad)',
    'tf': 'subscribes `/tf` and `/tf_static`; the orientation of `tf.child_frame` in '
          '`tf.parent_frame` composed along the TF tree, as tf2 '
          '`lookupTransform(parent, child, Time(0))` gives it, stamped with that time '
          '([docs/tf.md](docs/tf.md))',
}
"""What else a user needs to know of an input type (by ``input_type``; none for the others)."""

OUTPUT_CONTENTS = {
    'quaternion': 'unit quaternion, w >= 0 (or sign-continuous over time with '
                  '`quaternion.continuity`)',
    'euler': 'x, y, z = first, second, third angle of `euler.sequence`; first and third in '
             '(-pi, pi] (or unwrapped with `euler.unwrap`), the middle in [-pi/2, pi/2] '
             '(Tait-Bryan) or [0, pi] (proper Euler); degrees with `euler.degrees`',
    'rotation_vector': 'unit axis times angle in [0, pi] (rad)',
    'axis_angle': '`[x, y, z, angle]`: unit axis and angle in [0, pi] (rad), axis (1, 0, 0) '
                  'for the identity; one layout dimension `axis_angle` (size 4); no header',
    'matrix': 'the rotation matrix (body to world) row-major; layout dimensions `rows` '
              '(size 3, stride 9) and `cols` (size 3, stride 3); no header',
    'angular_velocity': 'rad/s in `angular_velocity.output_frame`',
    'euler_rates': 'time derivatives of the three Euler angles (rad/s, or deg/s with '
                   '`euler.degrees`)',
    'quaternion_rate': 'dq/dt (1/s) of the published quaternion',
    'euler_stddev': 'one standard deviation of each angle of `euler.sequence` (first order, '
                    "from the input's orientation covariance about `covariance.frame` axes; "
                    'degrees with `euler.degrees`); inputs with a covariance only',
    'euler_covariance': '`sensor_msgs/MagneticField` used as a stamped vector with '
                        'covariance: `magnetic_field` = the Euler angles (as `euler`), '
                        '`magnetic_field_covariance` = their 3 x 3 covariance, row-major '
                        '(rad^2, or deg^2 with `euler.degrees`); inputs with a covariance only',
}
"""The published numbers of each output, in words (by output name)."""


def _row(cells):
    return '| ' + ' | '.join(cell.replace('|', '\\|') for cell in cells) + ' |'


def _table(header, rows):
    return '\n'.join([_row(header), _row(['---'] * len(header)), *map(_row, rows)])


def _yaml_value(value):
    if isinstance(value, bool):
        return 'true' if value else 'false'
    if isinstance(value, tuple):
        return '[' + ', '.join(repr(v) if isinstance(v, float) else v for v in value) + ']'
    if value == '':
        return "''"
    return f'{value:g}' if isinstance(value, float) else str(value)


def input_types_table() -> str:
    """Return the Markdown table of the values of ``input_type``."""
    forms = {registry.QUATERNION: 'quaternion', registry.EULER: 'Euler angles',
             registry.ROTATION_VECTOR: 'rotation vector'}
    return _table(
        ['input_type', 'message', 'orientation', 'angular velocity from', 'notes'],
        [[f'`{entry.name}`', entry.type_name,
          f'`{entry.orientation_field}` ({forms[entry.orientation_form]})',
          'finite difference' if entry.angular_velocity_field is None
          else f'`{entry.angular_velocity_field}`', INPUT_NOTES.get(entry.name, '')]
         for entry in registry.INPUTS.values()])


def outputs_table() -> str:
    """Return the Markdown table of the values allowed in ``outputs``."""
    return _table(
        ['output', 'message', 'content'],
        [[f'`{entry.name}`', entry.type_name, OUTPUT_CONTENTS[entry.name]]
         for entry in registry.OUTPUTS.values()])


def parameters_table() -> str:
    """Return the Markdown table of the node's parameters."""
    return _table(
        ['parameter', 'default', 'allowed', 'meaning'],
        [[f'`{spec.name}`', f'`{_yaml_value(spec.default)}`', spec.constraints,
          spec.description] for spec in PARAMETERS])


def main() -> None:
    """Print the three tables, as they stand in the README."""
    print(input_types_table(), outputs_table(), parameters_table(), sep='\n\n')


if __name__ == '__main__':
    main()
