"""
Tests of rotation_node.markdown_tables: the documentation agrees with the registry.

The README's tables of input types, outputs and parameters are the rendered
ones (regenerate them with ``python -m rotation_node.markdown_tables``), the
shipped parameters file names every input type and output in its comments, and
package.xml depends on the package of every message type the node uses.
"""
from pathlib import Path
import re
from xml.etree import ElementTree

import pytest
from rotation_node import markdown_tables, registry
from rotation_node.parameters import PARAMETERS

ROOT = Path(__file__).resolve().parent.parent


@pytest.mark.parametrize('render', [
    markdown_tables.input_types_table, markdown_tables.outputs_table,
    markdown_tables.parameters_table])
def test_readme_holds_the_rendered_table(render):
    assert render() in (ROOT / 'README.md').read_text()


def test_tables_have_a_row_per_entry():
    rows = {render: render().splitlines()[2:] for render in (
        markdown_tables.input_types_table, markdown_tables.outputs_table,
        markdown_tables.parameters_table)}
    assert [row.split(' | ')[0] for row in rows[markdown_tables.input_types_table]] == [
        f'| `{name}`' for name in registry.INPUTS]
    assert [row.split(' | ')[0] for row in rows[markdown_tables.outputs_table]] == [
        f'| `{name}`' for name in registry.OUTPUTS]
    assert [row.split(' | ')[0] for row in rows[markdown_tables.parameters_table]] == [
        f'| `{spec.name}`' for spec in PARAMETERS]
    for table in rows.values():   # a '|' inside a cell is escaped
        for row in table:
            assert len(re.split(r'(?<!\\)\|', row)) == len(re.split(r'(?<!\\)\|', table[0]))


def test_the_words_of_the_tables_name_only_registry_entries():
    assert set(markdown_tables.INPUT_NOTES) <= set(registry.INPUTS)
    assert set(markdown_tables.OUTPUT_CONTENTS) == set(registry.OUTPUTS)


def _comment_before(text, key):
    """Return the comment lines just above ``key:`` in a YAML text."""
    lines = text.splitlines()
    index = next(i for i, line in enumerate(lines) if line.strip().startswith(key + ':'))
    comment = []
    while lines[index - 1].strip().startswith('#'):
        index -= 1
        comment.insert(0, lines[index])
    return ' '.join(comment)


def test_parameters_file_comments_name_every_input_type_and_output():
    text = (ROOT / 'config' / 'params.yaml').read_text()
    input_comment = _comment_before(text, 'input_type')
    output_comment = _comment_before(text, 'outputs')
    for name in registry.INPUTS:
        assert re.search(rf'\b{name}\b', input_comment), name
    for name in registry.OUTPUTS:
        assert re.search(rf'\b{name}\b', output_comment), name


def test_package_xml_depends_on_every_message_package():
    root = ElementTree.parse(ROOT / 'package.xml').getroot()
    depends = {element.text for element in root.findall('exec_depend')}
    used = {entry.type_name.split('/')[0]
            for entry in [*registry.INPUTS.values(), *registry.OUTPUTS.values()]}
    assert used <= depends
