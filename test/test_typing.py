"""
The public API is typed: every public function annotated, and mypy clean on the package.

mypy runs with the configuration in setup.cfg (``[mypy]``) and caches in
``.mypy_cache`` (ignored by git): a first run takes ~20 s, later ones a few.
"""
import ast
import configparser
import os
import subprocess
import sys
import textwrap

import pytest

# Starts processes or builds packages: not in the edit-test loop (-m "not slow").
pytestmark = pytest.mark.slow

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PACKAGE = os.path.join(ROOT, 'rotation_node')


def _is_public(name):
    return not name.startswith('_') or (name.startswith('__') and name.endswith('__'))


def _is_static(function):
    return any(isinstance(d, ast.Name) and d.id == 'staticmethod'
               for d in function.decorator_list)


def unannotated_functions(source, module=''):
    """
    Return ``module:line name`` of each public function or method lacking an annotation.

    Public: a module-level function or a method of a public class (at any
    nesting of public classes) whose name has no leading underscore, or a
    dunder method. Every parameter but ``self``/``cls`` needs an annotation,
    and the return type too, except for an ``__init__`` with annotated parameters (as
    mypy checks it).
    """
    missing = []

    def visit(body, prefix, in_class):
        for node in body:
            if isinstance(node, ast.ClassDef) and _is_public(node.name):
                visit(node.body, f'{prefix}{node.name}.', True)
            elif (isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef))
                    and _is_public(node.name)):
                args = node.args
                params = args.posonlyargs + args.args + args.kwonlyargs
                if in_class and params and not _is_static(node):
                    params = params[1:]
                params += [p for p in (args.vararg, args.kwarg) if p is not None]
                bare = [p.arg for p in params if p.annotation is None]
                returns = node.returns is not None or (node.name == '__init__' and params)
                if bare or not returns:
                    what = ', '.join(bare + ([] if returns else ['return']))
                    missing.append(f'{module}:{node.lineno} {prefix}{node.name} ({what})')

    visit(ast.parse(source).body, '', False)
    return missing


def package_modules():
    """Yield every Python file of the runtime package, relative to the repository."""
    for directory, _, files in os.walk(PACKAGE):
        for name in sorted(files):
            if name.endswith('.py'):
                yield os.path.relpath(os.path.join(directory, name), ROOT)


def test_every_public_function_of_the_package_is_annotated():
    missing = []
    for module in package_modules():
        with open(os.path.join(ROOT, module), encoding='utf-8') as f:
            missing += unannotated_functions(f.read(), module)
    assert not missing, 'public functions without type annotations:\n' + '\n'.join(missing)


def test_the_annotation_check_finds_what_is_missing():
    source = textwrap.dedent("""
        def typed(a: int, *args: int, b: str = '', **kw: float) -> None: ...
        def no_return(a: int): ...
        def bare_parameter(a, b: int) -> int: ...
        def _private(a): ...
        class Public:
            def __init__(self, a: int): ...
            def method(self, a) -> int: ...
            @staticmethod
            def static(a) -> int: ...
            @classmethod
            def build(cls) -> 'Public': ...
            def __len__(self): ...
            class Inner:
                def method(self, *args) -> None: ...
            class Bare:
                def __init__(self): ...
        class _Private:
            def method(self, a): ...
    """)
    assert unannotated_functions(source, 'm') == [
        'm:3 no_return (return)', 'm:4 bare_parameter (a)', 'm:8 Public.method (a)',
        'm:10 Public.static (a)', 'm:13 Public.__len__ (return)',
        'm:15 Public.Inner.method (args)', 'm:17 Public.Bare.__init__ (return)']


def test_py_typed_marks_the_package_as_typed():
    assert os.path.isfile(os.path.join(PACKAGE, 'py.typed'))


def test_no_module_of_the_package_is_exempt_from_mypys_checks():
    config = configparser.ConfigParser()
    config.read(os.path.join(ROOT, 'setup.cfg'))
    assert config['mypy'].getboolean('check_untyped_defs')
    exempt = [section for section in config.sections() if section.startswith('mypy-')
              and 'rotation_node' in section and (
                  config[section].getboolean('ignore_errors', False)
                  or not config[section].getboolean('check_untyped_defs', True))]
    assert not exempt, f'setup.cfg exempts {exempt} from the checks of mypy'


def test_mypy_finds_no_error_in_the_package():
    result = subprocess.run(
        [sys.executable, '-m', 'mypy', '--config-file', os.path.join(ROOT, 'setup.cfg')],
        cwd=ROOT, capture_output=True, text=True, timeout=240)
    assert result.returncode == 0, result.stdout + result.stderr
