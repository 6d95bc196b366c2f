"""ament_flake8 on the whole package with ament's own configuration, as ``colcon test`` runs it."""
from pathlib import Path

import pytest

# Starts processes or builds packages: not in the edit-test loop (-m "not slow").
pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parent.parent
#: Not sources of the package: the environment, colcon's and the demo's outputs.
EXCLUDE = ('.venv', '.venv-jazzy', 'build', 'install', 'log', 'out')


@pytest.mark.flake8
@pytest.mark.linter
def test_flake8():
    # Imported here, as test_pep257's linter: not paid by runs that skip this test.
    from ament_flake8.main import main_with_errors
    rc, errors = main_with_errors(argv=[str(ROOT), '--exclude', *EXCLUDE])
    assert rc == 0, f'{len(errors)} code style errors / warnings:\n' + '\n'.join(errors)
