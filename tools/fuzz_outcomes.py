#!/usr/bin/env python3
"""
Print the outcome table of the damaged-bag corpus (test/fuzz_corpus.py), or reproduce one case.

Run from the checkout, with its code first on the path::

    PYTHONPATH=$PWD python tools/fuzz_outcomes.py             # tables + distinct failures
    PYTHONPATH=$PWD python tools/fuzz_outcomes.py --only sqlite3
    PYTHONPATH=$PWD python tools/fuzz_outcomes.py --case mcap-zstd.swap.2 --keep /tmp/case

``--case`` writes the damaged input of one case into ``--keep`` (its name is
``<source>.<damage>.<n>``, as the test's failure messages and the table's
failure list give it) and runs its commands in this process, with the full
traceback of anything that escapes ``rotation_bag``.
"""
import argparse
import os
import sys
import tempfile

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))),
                                'test'))

import fuzz_corpus  # noqa: E402  (test/ is put on the path first)


def _reproduce(case, sources, directory):
    import traceback
    input_path, description = fuzz_corpus.materialize(case, sources, directory)
    print(f'{case.case_id}: {input_path} ({description}); seed {case.seed}')
    params = os.path.join(directory, 'params.yaml')
    with open(params, 'w') as stream:
        stream.write(fuzz_corpus.PARAMS_YAML)
    fuzz_corpus.limit_address_space()   # as in the test's child: 1 GB more at most
    for command in case.commands:
        out = os.path.join(directory, f'out_{command}')
        argv = fuzz_corpus.command_line(command, input_path, out, params)
        os.makedirs(out, exist_ok=True)
        print(f'$ rotation_bag {" ".join(argv)}')
        status, stderr, escaped = fuzz_corpus.run_main(argv, {})
        print(stderr, end='')
        if escaped is not None:
            traceback.print_exception(escaped)
        print(f'-> exit {status}' if escaped is None else '-> escaped')


def main():
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--only', metavar='TEXT', help='only cases whose id or format has TEXT')
    parser.add_argument('--case', metavar='ID', help='reproduce one case (see --keep)')
    parser.add_argument('--keep', metavar='DIR', help='where --case writes its input')
    parser.add_argument('--json', metavar='FILE', help='also write every result as JSON')
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix='fuzz_outcomes.') as directory:
        sources = fuzz_corpus.build_sources(os.path.join(directory, 'sources'))
        cases = fuzz_corpus.corpus(sources)
        if args.case:
            case, = [case for case in cases if case.case_id == args.case]
            _reproduce(case, sources, args.keep or os.path.join(directory, 'case'))
            return
        if args.only:
            cases = [case for case in cases if args.only in case.case_id
                     or args.only in case.bag_format]
        results = fuzz_corpus.run_cases(cases, sources, os.path.join(directory, 'run'))
    if args.json:
        import json
        with open(args.json, 'w') as stream:
            json.dump(results, stream, indent=1)
    plotted = f'plot (one case in {fuzz_corpus.PLOT_EVERY} of each source)'
    for command, title in (('convert', 'convert'), ('play', 'play (read path, no ROS graph)'),
                           ('plot', plotted)):
        print(f'\n{title}\n')
        print(fuzz_corpus.outcome_table(results, command))
    summary = fuzz_corpus.failure_summary(results, limit=200)
    print('\nfailures\n' if summary else '\nno failures')
    print(summary)
    below = fuzz_corpus.below_oracle_summary(results)
    print('\nexit 0, fewer messages than the independent readers read and decode '
          '(informational, not a failure of the test)\n')
    print(below or 'none')


if __name__ == '__main__':
    main()
