"""
Fix the mechanical findings of ament_flake8 and ament_pep257 in place.

    .venv/bin/python tools/lint_fix.py [PATH ...]      (default: the repository)

- I100/I101 (import order): ``isort`` with the ``[isort]`` settings of setup.cfg, on the
  files that have such findings only;
- D413 (blank line after the last docstring section): the blank line is added;
- D401 (imperative first line) where the summary starts with a noun phrase
  ("The x ...", "Unit quaternion ..."): it becomes "Return the x ...";
- D403 (first word capitalised) where the first word is an identifier: it is quoted
  as code (````convert`` reads ...``).

What it cannot do (long lines, argument descriptions, wording) it leaves for a person;
run the linters again afterwards (``test/test_flake8.py``, ``test/test_pep257.py``).
"""
import ast
import os
import re
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BIN = os.path.dirname(sys.executable)
EXCLUDE = ('.venv', 'build', 'install', 'log', 'out')
#: Summaries starting with these words become "Return <word> ...".
NOUN_STARTS = frozenset({'The', 'A', 'An', 'What', 'Where', 'How', 'Whether', 'Which', 'One',
                         'Two', 'Every', 'Each', 'All'})
QUOTES_ONLY = frozenset({'"""', "'''", 'r"""'})


def findings(tool, paths, pattern):
    """Return the ``re.Match`` of ``pattern`` for each line a linter prints (stdout + stderr)."""
    result = subprocess.run([os.path.join(BIN, tool), '--exclude', *EXCLUDE, '--', *paths],
                            capture_output=True, text=True, cwd=ROOT)
    lines = (result.stdout + result.stderr).splitlines()
    return [m for m in map(re.compile(pattern).match, lines) if m]


def sort_imports(paths):
    """Run isort on the files with import-order findings; return their number."""
    files = sorted({m.group(1) for m in findings('ament_flake8', paths,
                                                 r'(\S+\.py):\d+:\d+: I10[01] ')})
    if files:
        subprocess.run([os.path.join(BIN, 'isort'), '--settings-path', ROOT, '--quiet', *files],
                       check=True, cwd=ROOT)
    return len(files)


def fix_docstrings(paths):
    """Fix D413, D401 and D403 findings; return the findings left to a person."""
    todo = {}
    pattern = (r'(\S+\.py):(\d+) (?:in .*|at module level): (D401|D403|D413): '
               r".*?(?:found '(.*)'\))?$")
    for m in findings('ament_pep257', paths, pattern):
        todo.setdefault(m.group(1), []).append((int(m.group(2)), m.group(3), m.group(4)))
    left = []
    for path, items in todo.items():
        with open(os.path.join(ROOT, path)) as stream:
            source = stream.read()
        text = source.splitlines(keepends=True)
        ends = _docstring_ends(source)
        # From the bottom up, so that inserted lines do not move the ones still to fix.
        for lineno, code, _ in sorted(items, reverse=True):
            fixed = lineno in ends and _fix(text, lineno - 1, ends[lineno] - 1, code)
            if not fixed:
                left.append(f'{path}:{lineno}: {code}')
        with open(os.path.join(ROOT, path), 'w') as stream:
            stream.write(''.join(text))
    return left


def _docstring_ends(source):
    """Return ``{first line: last line}`` of the docstrings in a module's source."""
    ends = {}
    for node in ast.walk(ast.parse(source)):
        body = getattr(node, 'body', None)
        if isinstance(body, list) and body and isinstance(body[0], ast.Expr) \
                and isinstance(body[0].value, ast.Constant) \
                and isinstance(body[0].value.value, str):
            ends[body[0].lineno] = body[0].end_lineno
    return ends


def _fix(text, start, end, code):
    """Fix one finding of the docstring on ``text[start:end + 1]``; return whether it could."""
    if code == 'D413':
        closing = text[end]
        indent = closing[:len(closing) - len(closing.lstrip())]
        if closing.strip() in QUOTES_ONLY:
            text.insert(end, '\n')
        else:
            text[end:end + 1] = [closing.rstrip()[:-3].rstrip() + '\n', '\n', indent + '"""\n']
        return True
    line_index = start + 1 if text[start].strip() in QUOTES_ONLY else start
    match = re.match(r'(\s*(?:r?""")?)(\S+)(.*)', text[line_index], re.S)
    if match is None:
        return False
    head, first, rest = match.groups()
    if code == 'D403' and first.isidentifier():
        text[line_index] = f'{head}``{first}``{rest}'
    elif code == 'D401' and first in NOUN_STARTS:
        text[line_index] = f'{head}Return {first[0].lower()}{first[1:]}{rest}'
    elif code == 'D401' and first.isalpha() and first[0].isupper() and not first.isupper():
        text[line_index] = f'{head}Return the {first[0].lower()}{first[1:]}{rest}'
    else:
        return False
    return True


def main(argv=None):
    """Fix what can be fixed mechanically; print what is left; return the exit status."""
    paths = (sys.argv[1:] if argv is None else argv) or [ROOT]
    print(f'isort: {sort_imports(paths)} files')
    for finding in fix_docstrings(paths):
        print(f'left: {finding}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
