"""
``python -m rotation_dev.compare_figure [OUT.png]``: the figure of docs/compare.md.

Left: the four frames of ``R_ref(t) = W R_est(t + dt) M`` and which side each
rotation is on. Right: the sign of the time offset, on the angular rate
magnitudes of two synthetic streams (:mod:`rotation_dev.two_streams`) whose
estimate stamps the motion 0.25 s late (``dt = +0.25 s``), with the offset
``rotation_bag compare`` estimates from them. Default output: docs/compare.png.
"""
import io
import os
import sys

from matplotlib.figure import Figure
import numpy as np
from rotation_dev.paths import REPOSITORY
from rotation_dev.two_streams import two_streams
from rotation_node import comparison, kinematics
from rotation_node.bag.writing.atomic_file import AtomicFile

TIME_OFFSET_S = 0.25


def _frames(axis):
    axis.set_xlim(0, 10)
    axis.set_ylim(0, 7)
    axis.axis('off')
    boxes = {'estimate body': (2.0, 5.5), 'estimate world': (8.0, 5.5),
             'reference body': (2.0, 1.5), 'reference world': (8.0, 1.5)}
    for name, (x, y) in boxes.items():
        axis.text(x, y, name, ha='center', va='center', fontsize=11,
                  bbox={'boxstyle': 'round,pad=0.5', 'facecolor': '#eef3fb',
                        'edgecolor': '#4a6fa5'})

    def arrow(start, end, label, where, colour):
        axis.annotate('', xy=end, xytext=start,
                      arrowprops={'arrowstyle': '->', 'linewidth': 1.8, 'color': colour})
        axis.text(*where, label, ha='center', va='center', fontsize=11, color=colour)

    arrow((3.4, 5.5), (6.6, 5.5), 'R_est(t + dt)', (5.0, 6.0), 'tab:orange')
    arrow((3.4, 1.5), (6.6, 1.5), 'R_ref(t)', (5.0, 1.0), 'tab:blue')
    arrow((2.0, 2.1), (2.0, 4.9), 'M  (mounting)', (1.2, 3.5), 'tab:green')
    arrow((8.0, 4.9), (8.0, 2.1), 'W  (world\nalignment)', (9.0, 3.5), 'tab:red')
    axis.text(5.0, 3.5, 'R_ref(t) = W R_est(t + dt) M\n\nerror E = R_ref^T W R_est M:\n'
              'its rotation vector about the\nreference body axes', ha='center', va='center',
              fontsize=10)
    axis.set_title('Which side each rotation is on (R: body to world)')


def _offset(axis):
    streams = two_streams(3, duration=20.0, noise_ref_deg=0.3, noise_est_deg=0.3,
                          time_offset=TIME_OFFSET_S)
    found = comparison.estimate_time_offset(streams.t_ref, streams.q_ref, streams.t_est,
                                            streams.q_est)
    for t, q, label, style in ((streams.t_ref, streams.q_ref, 'reference |w_ref(t)|', '-'),
                               (streams.t_est, streams.q_est, 'estimate |w_est(t)|', '--')):
        rate = np.linalg.norm(kinematics.angular_velocity_from_quaternions(q, t), axis=1)
        middle = 0.5 * (t[1:] + t[:-1])
        width = 0.05 / np.median(np.diff(t))   # the same 50 ms Gaussian on both
        kernel = np.exp(-0.5 * (np.arange(-4 * int(width), 4 * int(width) + 1) / width) ** 2)
        smooth = np.convolve(rate, kernel / kernel.sum(), mode='same')
        window = (middle > 6.0) & (middle < 10.0)
        axis.plot(middle[window], smooth[window], style, label=label)
    axis.set_title(f'Time offset dt > 0: the estimate stamps the motion later\n(true dt = '
                   f'{TIME_OFFSET_S:+.3f} s, estimated {found.seconds:+.4f} s)')
    axis.set_xlabel('stamp (s)')
    axis.set_ylabel('angular rate magnitude (rad/s)')
    axis.grid(True, alpha=0.3)
    axis.legend(fontsize='small')


def figure_png():
    """Return the figure as PNG bytes."""
    figure = Figure(figsize=(12, 4.6), layout='constrained')
    left, right = figure.subplots(1, 2, gridspec_kw={'width_ratios': [1.1, 1.0]})
    _frames(left)
    _offset(right)
    output = io.BytesIO()
    figure.savefig(output, format='png', dpi=100)
    return output.getvalue()


def main(argv=None):
    """Write the figure; return the exit status."""
    argv = sys.argv[1:] if argv is None else argv
    path = argv[0] if argv else os.path.join(REPOSITORY, 'docs', 'compare.png')
    with AtomicFile(path, overwrite=True) as output:
        output.stream.write(figure_png())
    print(f'wrote {path}', file=sys.stderr)
    return 0


if __name__ == '__main__':
    sys.exit(main())
