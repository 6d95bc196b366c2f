"""
The damaged-bag corpus: every damaged input ends in one line or an honest note.

Bags of independent writers (the ``mcap`` library, ``rosbags``' rosbag2 and
ROS 1 writers), each damaged in seeded ways (flipped bytes, truncation, length
fields set to 2^31..2^64-1, zeroed regions, swapped records, TEXT rows in
sqlite3, garbage in ``metadata.yaml``; see ``fuzz_corpus``), are converted,
played (the read path; rclpy's publishers stood in for) and some plotted by
``rotation_bag`` in-process, in forked children allowed 1 GB more address space.
Every run must end with exit 0 and every message written read, or a note
saying what was not; or exit 1 and one line naming the input. Never a
traceback, never more memory, the input untouched, nothing left behind.
``tools/fuzz_outcomes.py`` prints the outcome table and reproduces a case.
"""
import os
import time

import fuzz_corpus
import pytest

FORMATS = ('mcap file', 'rosbag2 mcap', 'rosbag2 sqlite3', 'ROS 1 bag', 'metadata.yaml')
COMMANDS = ('convert', 'play', 'plot')


@pytest.fixture(scope='module')
def sources(tmp_path_factory):
    return fuzz_corpus.build_sources(str(tmp_path_factory.mktemp('fuzz_sources')))


@pytest.fixture(scope='module')
def results(sources, tmp_path_factory):
    """Every case of the corpus run once (all tests below read these results)."""
    return fuzz_corpus.run_cases(fuzz_corpus.corpus(sources), sources,
                                 str(tmp_path_factory.mktemp('fuzz_runs')))


@pytest.mark.slow
def test_layouts_tile_the_files_and_find_every_stored_message(sources):
    """The parsers that place the length-field damage read the files as their writers wrote."""
    for source in sources.values():
        with open(source.storage_file, 'rb') as stream:
            data = stream.read()
        layout = fuzz_corpus.layout_of(source, data)
        records = layout.records
        assert all(end == start for (_, end, _), (start, _, _) in zip(records, records[1:]))
        head, tail = {'mcap file': (8, 8), 'rosbag2 mcap': (8, 8), 'ROS 1 bag': (13, 0),
                      'rosbag2 sqlite3': (0, 0)}[source.bag_format]
        assert (records[0][0], records[-1][1]) == (head, len(data) - tail), source.name
        stored_plainly = source.name in ('mcap-none', 'mcap-none-unchunked', 'rosbag2-mcap',
                                         'rosbag2-sqlite3', 'ros1-none')
        found = sum(what == 'message string length' for _, _, _, what in layout.lengths)
        assert found == (sum(fuzz_corpus.WRITTEN.values()) if stored_plainly else found)
        assert all(offset + width <= len(data) for offset, width, _, _ in layout.lengths)


@pytest.mark.slow
def test_the_corpus_is_seeded_and_damages_its_inputs(sources, tmp_path):
    cases = fuzz_corpus.corpus(sources)
    assert len(cases) >= 250
    again = fuzz_corpus.build_sources(str(tmp_path / 'again'))
    assert {name: fuzz_corpus.tree_hash(source.path) for name, source in again.items()} == {
        name: fuzz_corpus.tree_hash(source.path) for name, source in sources.items()}
    assert [case.case_id for case in fuzz_corpus.corpus(again)] == [
        case.case_id for case in cases]
    for case in cases[::7]:
        first, _ = fuzz_corpus.materialize(case, sources, str(tmp_path / 'a' / case.case_id))
        second, _ = fuzz_corpus.materialize(case, sources, str(tmp_path / 'b' / case.case_id))
        digest = fuzz_corpus.tree_hash(first)
        assert fuzz_corpus.tree_hash(second) == digest
        untouched = fuzz_corpus.tree_hash(sources[case.source].path)
        if case.damage == 'none':
            assert digest == untouched
        elif not case.damage.startswith('zero'):   # zeros over zeros change nothing
            assert digest != untouched, case.case_id


@pytest.mark.slow
def test_undamaged_bags_are_read_whole(results):
    """The control of the classification: every source as written converts, plays, plots clean."""
    controls = [r for r in results if r['damage'] == 'none']
    assert {r['source'] for r in controls} == {r['source'] for r in results}
    assert [(r['case'], r['command'], r['detail']) for r in controls
            if r['klass'] != 'clean'] == []
    # The independent readers (the informational check) read them whole too.
    written = fuzz_corpus.WRITTEN
    assert [r['case'] for r in controls if r['oracle'] != (
        written['/imu'] if r['command'] == 'plot' else sum(written.values()))] == []


@pytest.mark.slow
def test_the_independent_readers_stop_where_a_file_is_cut(sources, tmp_path):
    for name in ('mcap-none', 'mcap-none-unchunked'):   # (rosbags' readers need an index)
        source = sources[name]
        with open(source.path, 'rb') as stream:
            data = stream.read()
        cut = tmp_path / os.path.basename(source.path)
        cut.write_bytes(data[:len(data) // 2])
        counts = fuzz_corpus.oracle_counts(str(cut), source)
        assert 0 < sum(counts.values()) < sum(fuzz_corpus.WRITTEN.values()), name


@pytest.mark.slow
@pytest.mark.parametrize('command', COMMANDS)
@pytest.mark.parametrize('bag_format', FORMATS)
def test_damaged_bags_end_in_one_line_or_a_note(results, bag_format, command):
    runs = [r for r in results if r['format'] == bag_format and r['command'] == command]
    assert runs
    failed = fuzz_corpus.failures(runs)
    assert not failed, (
        f'{len(failed)} of {len(runs)} damaged {bag_format} inputs of {command} failed '
        f'(reproduce one: PYTHONPATH=$PWD python tools/fuzz_outcomes.py --case ID):\n'
        + fuzz_corpus.failure_summary(failed))


@pytest.mark.slow
def test_the_outcome_table_counts_every_run_once(results):
    for command in COMMANDS:
        rows = [line.split('|')[1:-1] for line in
                fuzz_corpus.outcome_table(results, command).splitlines()[2:]]
        for row in rows:   # the last column (exit 0 below the independent readers) is apart
            assert int(row[2]) == sum(int(cell) for cell in row[3:-1] if cell.strip())
        assert int(rows[-1][2]) == sum(r['command'] == command for r in results)
    assert sum(r['command'] == 'convert' for r in results) == len({r['case'] for r in results})


_ERROR = 'rotation_bag convert: error: /bags/in.mcap is corrupt\n'
_NOTE = '/bags/in.mcap: 1 message of /status lost at offset 9\n'


@pytest.mark.parametrize('expected, command, status, stderr, more', [
    ('memory', 'convert', None, '', {'escaped': MemoryError()}),
    ('traceback', 'convert', None, '', {'escaped': KeyError('x')}),
    ('traceback', 'plot', 1, 'Traceback (most recent call last):\n', {}),
    ('error line', 'convert', 1, _ERROR, {}),
    ('bad error line', 'convert', 1, 'rotation_bag convert: error: a message is bad\n', {}),
    ('bad error line', 'convert', 1, _NOTE + _ERROR, {}),
    ('error line', 'play', 1, _NOTE + _ERROR.replace('convert', 'play'), {}),
    ('left behind', 'convert', 1, _ERROR, {'left': ['converted.mcap.part']}),
    ('bad exit', 'play', 2, '', {}),
    ('silent loss', 'play', 0, '', {'published': {'/imu': 40, '/status': 7}}),
    ('note', 'play', 0, _NOTE, {'published': {'/imu': 40, '/status': 7}}),
    ('clean', 'play', 0, '', {'published': {'/imu': 40, '/status': 8}}),
    ('silent loss', 'plot', 0, 'plotted 39 messages of /imu to p.png\n', {'left': ['plot.png']}),
    ('counts disagree', 'plot', 0, 'plotted 41 messages of /imu to p.png\n',
     {'left': ['plot.png']}),
])
def test_each_outcome_is_classified_as_what_it_is(
        tmp_path, expected, command, status, stderr, more):
    for name in more.get('left', ()):
        (tmp_path / name).write_bytes(b'')
    klass, _ = fuzz_corpus.classify(command, '/bags/in.mcap', status, stderr,
                                    more.get('escaped'), str(tmp_path), more.get('published', {}))
    assert klass == expected


@pytest.mark.slow
def test_a_crash_or_a_hang_costs_one_case_and_the_next_runs(sources, tmp_path, monkeypatch):
    cases = [case for case in fuzz_corpus.corpus(sources) if case.damage == 'truncate'][:3]
    real_run_case = fuzz_corpus.run_case

    def run_case(case, *args):   # runs in the child
        if case is cases[0]:
            os._exit(9)
        if case is cases[1]:
            time.sleep(60)
        return real_run_case(case, *args)

    monkeypatch.setattr(fuzz_corpus, 'run_case', run_case)
    results = fuzz_corpus.run_cases(cases, sources, str(tmp_path), timeout_s=3)
    outcomes = [{r['klass'] for r in results if r['case'] == case.case_id} for case in cases]
    assert outcomes[:2] == [{'crash'}, {'hang'}]
    assert outcomes[2] and outcomes[2] <= set(fuzz_corpus.ACCEPTED)
    assert len(results) == sum(len(case.commands) for case in cases)
