"""ament_pep257 on the whole package, with ament's own convention (as ``colcon test`` runs it)."""
from pathlib import Path

import pytest

# Starts processes or builds packages: not in the edit-test loop (-m "not slow").
pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parent.parent
#: Not sources of the package: the environment, colcon's and the demo's outputs.
EXCLUDE = ('.venv', '.venv-jazzy', 'build', 'install', 'log', 'out')


@pytest.mark.linter
@pytest.mark.pep257
def test_pep257():
    # Imported here: pydocstyle's import (~0.5 s) is not paid by runs that skip this test.
    from ament_pep257.main import main
    rc = main(argv=[str(ROOT), '--exclude', *EXCLUDE])
    assert rc == 0, 'found code style errors / warnings (listed above)'
