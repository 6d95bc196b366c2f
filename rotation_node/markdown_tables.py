"""
The README's tables of input types, outputs and parameters, rendered from the code.

The tables are derived from :data:`rotation_node.messages.INPUTS`,
:data:`rotation_node.messages.OUTPUTS` and
:data:`rotation_node.parameters.PARAMETERS`; the test suite checks that the
README holds them as rendered here. After adding an entry, print them with::

    python -m rotation_node.markdown_tables
"""
from rotation_node import messages
from rotation_node.parameters import PARAMETERS


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
    forms = {messages.QUATERNION: 'quaternion', messages.EULER: 'Euler angles',
             messages.ROTATION_VECTOR: 'rotation vector'}
    return _table(
        ['input_type', 'message', 'orientation', 'angular velocity from', 'notes'],
        [[f'`{entry.name}`', entry.type_name,
          f'`{entry.orientation_field}` ({forms[entry.orientation_form]})',
          entry.angular_velocity_source, entry.notes]
         for entry in messages.INPUTS.values()])


def outputs_table() -> str:
    """Return the Markdown table of the values allowed in ``outputs``."""
    return _table(
        ['output', 'message', 'content'],
        [[f'`{entry.name}`', entry.type_name, entry.description]
         for entry in messages.OUTPUTS.values()])


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
