"""
Development tools of a source checkout; not part of the installed ``rotation_node`` package.

The accuracy study (:mod:`rotation_dev.study`, run as ``python -m rotation_dev.study``),
the main job of the README (:mod:`rotation_dev.demo`, ``./run.sh main``) and the
hard-case corpus shared by the tests, the benchmarks and the study
(:mod:`rotation_dev.hard_cases`). They import test oracles (scipy, transforms3d,
mpmath) and files of the repository (``config/``, ``benchmarks/``), so they are run
from the repository root with the development environment of ``run.sh``; neither
``pip install .`` nor ``colcon build`` installs them.
"""
