"""
The accuracy-vs-time study and the performance summary (``python -m rotation_dev.study``).

Every conversion method users choose between (the textbook formulas,
Shepperd, Markley, SVD, tf2, PlotJuggler, transforms3d, scipy and this
package) is measured side by side on the hard cases of docs/numerics.md: time per
rotation against worst error in eps, the error taken against a 40-digit
mpmath truth. The attitude integrators are measured against exact truth over a
range of steps, and the repository's benchmarks are run for their ratios.

Modules: :mod:`.reference` (exact truth), :mod:`.methods` (the competing
methods), :mod:`.measure` (timing and errors per conversion family),
:mod:`.integration` (integrators), :mod:`.covariance` (first-order Euler
covariance against Monte Carlo), :mod:`.report` (``accuracy.md``,
``accuracy.png``), :mod:`.performance` (``performance.md``), :mod:`.cli`.

scipy, transforms3d and mpmath are study-time peers and references, imported
by the study (and the tests), never by the runtime package ``rotation_node``.
"""
