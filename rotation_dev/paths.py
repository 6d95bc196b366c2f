"""Where the repository's files are, for the development tools of a source checkout."""
import os

#: The repository root (the directory holding ``rotation_dev/``).
REPOSITORY = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
#: The benchmark scripts (they are not installed).
BENCHMARKS_DIR = os.path.join(REPOSITORY, 'benchmarks')


def config_path(*parts: str) -> str:
    """
    Return the path of a file under the repository's ``config/``.

    Parameters
    ----------
    *parts : str
        Path components below ``config/``, e.g. ``('scenes', 'tumbling_box.yaml')``.

    Returns
    -------
    str
        The joined path (whether or not the file exists).

    """
    return os.path.join(REPOSITORY, 'config', *parts)
