"""
Quaternion algebra: the scalar formulas every other module builds on.

Convention: ``q = (x, y, z, w)``, scalar last, Hamilton product, active
rotation mapping body coordinates to world coordinates. Any non-zero scale of a
quaternion represents the same rotation; every formula here either works on
ratios or rescales by a power of two first (exact), so quaternions scaled by
1e-160 or 1e+160 are handled without under- or overflow.

The scalar functions (tuples in, tuples out) are compiled with numba and
called from the loop kernels of every module; they assume finite, non-zero
input (the kernels check with :func:`quaternion_defect` first). The helpers
at the end (``call_unary``, ``call_binary``, ``run_staged``) are the one
Python-side path from public arguments to kernels: validation, output
allocation, batch schedules, threads and error reporting.
"""
import math
import os
from concurrent.futures import ThreadPoolExecutor

import numpy as np
from numba import njit, types
from numba.core.errors import TypingError
from numba.extending import overload

from ._validation import NON_FINITE, OK, ZERO_NORM, broadcast_pair, float_array, raise_sample_error

# Every compiled function is inlined into its callers (numba IR inlining, not
# left to LLVM). A helper that is called rather than inlined costs a call per
# sample and, when an array is live across it (the kernels' inputs and
# outputs always are), an atomic reference-count increment and decrement per
# call: 2-4x the whole per-sample cost of most kernels, measured.
# (Inlined callees cannot be called with ``*args``.)
jit = njit(cache=True, nogil=True, error_model='numpy', inline='always')


def samples(a, sample_ndim):
    """
    The C-contiguous ``a`` as a stack of samples: shape ``(n,) + a.shape[-sample_ndim:]``.

    How kernels see their arguments, whatever the leading shape. In compiled
    code (the overload below) one sample and a one-dimensional stack are
    viewed for free; only more leading dimensions take a ``reshape``, which
    calls a C helper in numba (~30 ns, as much as a whole sample's
    conversion). ``sample_ndim`` must be a constant.
    """
    return a.reshape((-1,) + a.shape[a.ndim - sample_ndim:])


@overload(samples, inline='always', prefer_literal=True)
def _samples_overload(a, sample_ndim):
    if not isinstance(sample_ndim, types.IntegerLiteral):
        raise TypingError('samples(): `sample_ndim` must be a constant.')
    k = sample_ndim.literal_value
    if not (isinstance(a, types.Array) and a.layout == 'C' and a.ndim >= k):
        raise TypingError(f'samples(): expected a C-contiguous array of >= {k} dimensions, got {a}.')
    if a.ndim == k:   # one sample
        return lambda a, sample_ndim: a[None, ...]
    if a.ndim == k + 1:   # already a stack
        return lambda a, sample_ndim: a
    start = a.ndim - k
    return lambda a, sample_ndim: a.reshape((-1,) + a.shape[start:])


@jit
def quaternion_defect(x, y, z, w):
    """Defect code of a quaternion: OK, NON_FINITE or ZERO_NORM."""
    if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(z) and math.isfinite(w)):
        return NON_FINITE
    if x == 0.0 and y == 0.0 and z == 0.0 and w == 0.0:
        return ZERO_NORM
    return OK


@jit
def vector_defect(x, y, z):
    """Defect code of a 3-vector: OK or NON_FINITE."""
    if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(z)):
        return NON_FINITE
    return OK


# Magnitudes whose squares and sums of squares are normal, finite doubles.
_SAFE_LOW = 2.0 ** -500
_SAFE_HIGH = 2.0 ** 500


@jit
def binary_exponent(m):
    """``e`` with ``m = f 2**e``, f in [0.5, 1): scaling by ``2**-e`` is exact."""
    return math.frexp(m)[1]


@jit
def scaled_quaternion(x, y, z, w):
    """
    The same quaternion, rescaled exactly so that sums of squares neither over- nor underflow.

    Unchanged when the largest component is within [2^-500, 2^500]; otherwise
    scaled by a power of two (exact, subnormals included) to [0.5, 1).
    """
    m = max(abs(x), abs(y), abs(z), abs(w))
    if _SAFE_LOW < m < _SAFE_HIGH:
        return x, y, z, w
    e = -binary_exponent(m)
    return math.ldexp(x, e), math.ldexp(y, e), math.ldexp(z, e), math.ldexp(w, e)


@jit
def vector_norm(x, y, z):
    """Euclidean norm of a 3-vector without under- or overflow."""
    m = max(abs(x), abs(y), abs(z))
    if _SAFE_LOW < m < _SAFE_HIGH:
        return math.sqrt(x * x + y * y + z * z)
    if m == 0.0:
        return 0.0
    e = binary_exponent(m)
    x, y, z = math.ldexp(x, -e), math.ldexp(y, -e), math.ldexp(z, -e)
    return math.ldexp(math.sqrt(x * x + y * y + z * z), e)


@jit
def needs_sign_flip(x, y, z, w):
    """
    Whether ``-q`` is the canonical sign of ``q``.

    Canonical: w > 0, or w == 0 and the first non-zero of x, y, z > 0. The rule
    makes the output unique: q and -q map to the same result.
    """
    return w < 0.0 or (w == 0.0 and (x < 0.0 or (x == 0.0 and (y < 0.0 or (y == 0.0 and z < 0.0)))))


@jit
def unit_quaternion(x, y, z, w):
    """``q / |q|`` with its sign kept; any non-zero norm (exact power-of-two rescaling first)."""
    x, y, z, w = scaled_quaternion(x, y, z, w)
    n = math.sqrt(x * x + y * y + z * z + w * w)
    return x / n, y / n, z / n, w / n


@jit
def canonical_unit_quaternion(x, y, z, w):
    """Unit quaternion with the canonical sign (see :func:`needs_sign_flip`)."""
    x, y, z, w = unit_quaternion(x, y, z, w)
    if needs_sign_flip(x, y, z, w):
        x, y, z, w = -x, -y, -z, -w
    return x, y, z, w + 0.0  # + 0.0 turns w = -0.0 into 0.0


@jit
def product(px, py, pz, pw, qx, qy, qz, qw):
    """Hamilton product ``p (x) q``."""
    return (pw * qx + px * qw + py * qz - pz * qy,
            pw * qy - px * qz + py * qw + pz * qx,
            pw * qz + px * qy - py * qx + pz * qw,
            pw * qw - px * qx - py * qy - pz * qz)


@jit
def conjugate_product(px, py, pz, pw, qx, qy, qz, qw):
    """
    ``p* (x) q``, the rotation from ``p`` to ``q``, with each cancelling pair grouped.

    The vector part is ``(p_s q_v - q_s p_v) - p_v x q_v``: each bracket is a
    difference of the same two products when ``q = +-p``, so the vector part of
    a rotation relative to itself is exactly zero.
    """
    return ((pw * qx - px * qw) - (py * qz - pz * qy),
            (pw * qy - py * qw) - (pz * qx - px * qz),
            (pw * qz - pz * qw) - (px * qy - py * qx),
            pw * qw + px * qx + py * qy + pz * qz)


@jit
def rotated_vector(x, y, z, w, vx, vy, vz):
    """
    ``R(q) v`` for a unit quaternion: ``v + w t + u x t`` with ``t = 2 u x v``.

    A vector beyond 2^500 is rotated at an exactly rescaled size, so that
    ``t`` cannot overflow where ``R v`` itself does not.
    """
    m = max(abs(vx), abs(vy), abs(vz))
    e = binary_exponent(m) if m > _SAFE_HIGH else 0
    vx, vy, vz = math.ldexp(vx, -e), math.ldexp(vy, -e), math.ldexp(vz, -e)
    tx = 2.0 * (y * vz - z * vy)
    ty = 2.0 * (z * vx - x * vz)
    tz = 2.0 * (x * vy - y * vx)
    return (math.ldexp(vx + w * tx + (y * tz - z * ty), e),
            math.ldexp(vy + w * ty + (z * tx - x * tz), e),
            math.ldexp(vz + w * tz + (x * ty - y * tx), e))


@jit
def half_angle_atan2(vector_norm_value, scalar):
    """Rotation angle ``2 atan2(|q_v|, |q_s|)`` in [0, pi]: ~1 ulp for every angle."""
    return 2.0 * math.atan2(vector_norm_value, abs(scalar))


@jit
def status(sample, argument, code):
    """Kernel status for a bad sample: ``(sample << 4) | (argument << 3) | code``."""
    return (sample << 4) | (argument << 3) | code


@jit
def first_status(a, b):
    """The first of two statuses that reports a bad sample (-1 if neither does)."""
    return a if a >= 0 else b


@jit
def quaternion_status(fq, s, argument):
    """Status of sample ``s`` of the flat quaternions ``fq`` (-1 when fine)."""
    code = quaternion_defect(fq[s, 0], fq[s, 1], fq[s, 2], fq[s, 3])
    return -1 if code == OK else status(s, argument, code)


@jit
def vector_status(fv, s, argument):
    """Status of sample ``s`` of the flat 3-vectors ``fv`` (-1 when fine)."""
    code = vector_defect(fv[s, 0], fv[s, 1], fv[s, 2])
    return -1 if code == OK else status(s, argument, code)


# ----------------------------------------------------------------- kernels
# Kernels take validated C-contiguous arrays of any (common) leading shape and
# a preallocated output, flatten them (free views), fill the output and return
# the status of the first bad sample, or -1. Allocating in Python and returning
# an int keeps a single-sample call near numba's dispatch floor.

@jit
def _product_kernel(p, q, out):
    fp, fq, fo = samples(p, 1), samples(q, 1), samples(out, 1)
    for s in range(fp.shape[0]):
        bad = first_status(quaternion_status(fp, s, 0), quaternion_status(fq, s, 1))
        if bad >= 0:
            return bad
        fo[s, 0], fo[s, 1], fo[s, 2], fo[s, 3] = product(
            fp[s, 0], fp[s, 1], fp[s, 2], fp[s, 3], fq[s, 0], fq[s, 1], fq[s, 2], fq[s, 3])
    return -1


@jit
def _conjugate_kernel(q, out):
    fq, fo = samples(q, 1), samples(out, 1)
    for s in range(fq.shape[0]):
        bad = quaternion_status(fq, s, 0)
        if bad >= 0:
            return bad
        fo[s, 0], fo[s, 1], fo[s, 2], fo[s, 3] = -fq[s, 0], -fq[s, 1], -fq[s, 2], fq[s, 3]
    return -1


@jit
def canonical_kernel(q, out):
    """Canonical unit quaternions of ``q`` into ``out``; returns the status."""
    fq, fo = samples(q, 1), samples(out, 1)
    for s in range(fq.shape[0]):
        bad = quaternion_status(fq, s, 0)
        if bad >= 0:
            return bad
        fo[s, 0], fo[s, 1], fo[s, 2], fo[s, 3] = canonical_unit_quaternion(
            fq[s, 0], fq[s, 1], fq[s, 2], fq[s, 3])
    return -1


@jit
def _distance_kernel(p, q, out):
    fp, fq, fo = samples(p, 1), samples(q, 1), samples(out, 0)
    for s in range(fp.shape[0]):
        bad = first_status(quaternion_status(fp, s, 0), quaternion_status(fq, s, 1))
        if bad >= 0:
            return bad
        px, py, pz, pw = scaled_quaternion(fp[s, 0], fp[s, 1], fp[s, 2], fp[s, 3])
        qx, qy, qz, qw = scaled_quaternion(fq[s, 0], fq[s, 1], fq[s, 2], fq[s, 3])
        ex, ey, ez, ew = conjugate_product(px, py, pz, pw, qx, qy, qz, qw)
        fo[s] = half_angle_atan2(vector_norm(ex, ey, ez), ew)
    return -1


@jit
def _rotate_kernel(q, v, out):
    fq, fv, fo = samples(q, 1), samples(v, 1), samples(out, 1)
    for s in range(fq.shape[0]):
        bad = first_status(quaternion_status(fq, s, 0), vector_status(fv, s, 1))
        if bad >= 0:
            return bad
        x, y, z, w = canonical_unit_quaternion(fq[s, 0], fq[s, 1], fq[s, 2], fq[s, 3])
        fo[s, 0], fo[s, 1], fo[s, 2] = rotated_vector(x, y, z, w, fv[s, 0], fv[s, 1], fv[s, 2])
    return -1


# ------------------------------------------------------------ public API

# Inputs of at least this many samples use a kernel's batch schedule, where
# it has one (the same count for every input type, so that a conversion and
# its route through quaternions agree bit for bit).
BATCH_SAMPLES = 1024


def is_batch(a, trailing):
    """Whether ``a`` (samples of shape ``trailing``) is large enough for a batch schedule."""
    return a.size >= BATCH_SAMPLES * math.prod(trailing)

# Samples per chunk of a staged batch: the intermediates stay in cache.
STAGE_CHUNK = 4096


def run_staged(n, width, first, transcendental, second):
    """
    Run a kernel split around vectorised transcendental functions, chunk by chunk.

    The batch schedule of a kernel whose scalar formula calls libm (``atan2``,
    ``sin``, ``cos``): a compiled loop computes the arguments, numpy's SIMD
    ufuncs (< 1 ulp, several times faster than scalar libm calls) evaluate
    them, and a second compiled loop finishes the formula. The formulas are
    the fused kernel's own scalar functions; only the schedule differs.

    Parameters
    ----------
    n : int
        Number of samples.
    width : int
        Arguments per sample.
    first : callable
        ``first(start, stop, y, x) -> status`` validates samples
        ``start:stop`` and fills the arguments ``y`` and ``x`` (``(m, width)``).
    transcendental : callable
        ``transcendental(y, x)`` evaluates in place, e.g. :func:`atan2_in_place`.
    second : callable
        ``second(start, stop, y, x)`` turns the results into output.

    Returns
    -------
    int
        The status of the first bad sample (with its index among the ``n``), or -1.
    """
    y = np.empty((min(n, STAGE_CHUNK), width))
    x = np.empty_like(y)
    for start in range(0, n, STAGE_CHUNK):
        stop = min(n, start + STAGE_CHUNK)
        yc, xc = y[:stop - start], x[:stop - start]
        bad = first(start, stop, yc, xc)
        if bad >= 0:
            return bad + (start << 4)
        transcendental(yc, xc)
        second(start, stop, yc, xc)
    return -1


def atan2_in_place(y, x):
    """``y <- atan2(y, x)``."""
    np.arctan2(y, x, out=y)


# Batches of at least this many samples are split across threads (the kernels
# release the GIL); ROTATION_NODE_THREADS overrides the number of threads.
THREADED_SAMPLES = 1 << 16
_threads = int(os.environ.get('ROTATION_NODE_THREADS', 0)) or len(os.sched_getaffinity(0))
_pool = None


def set_threads(n):
    """
    Set how many threads large batches (>= 65536 samples) are split across.

    Parameters
    ----------
    n : int
        1 runs everything in the calling thread. The default is the number of
        CPUs this process may use, or the environment variable
        ``ROTATION_NODE_THREADS``.
    """
    global _threads, _pool
    if int(n) < 1:
        raise ValueError(f'Expected `n` >= 1 threads, got {n!r}.')
    _threads = int(n)
    if _pool is not None:
        _pool.shutdown()
        _pool = None


def _run(kernel, inputs, trailings, out, out_trailing, args):
    """Run ``kernel(*inputs, out, *args)``, split across threads for large batches."""
    n = out.size // math.prod(out_trailing)
    if _threads == 1 or n < THREADED_SAMPLES:
        return kernel(*inputs, out, *args)
    global _pool
    if _pool is None:
        _pool = ThreadPoolExecutor(_threads, thread_name_prefix='rotation_node')
    flat_inputs = [a.reshape((n,) + t) for a, t in zip(inputs, trailings)]
    flat_out = out.reshape((n,) + out_trailing)
    bounds = np.linspace(0, n, _threads + 1).astype(int)
    jobs = [_pool.submit(kernel, *[a[lo:hi] for a in flat_inputs], flat_out[lo:hi], *args)
            for lo, hi in zip(bounds[:-1], bounds[1:])]
    for lo, job in zip(bounds[:-1], jobs):
        bad = job.result()
        if bad >= 0:
            return bad + (int(lo) << 4)
    return -1


# A single-sample call costs ~1 us in all, and numba's dispatch is a third of
# it, so the single-sample path passes numba what it types fastest: a scalar
# result is computed into shape (1,), a scalar argument passed as a float (a
# 0-d array costs ~170 ns more, a numpy scalar ~60 ns), and the names it uses
# are module globals (``np.empty`` looked up through the module costs ~30 ns).
_FLOAT64 = np.dtype(np.float64)
_NDARRAY = np.ndarray
_ONE = (1,)
new_array = np.empty


def is_single_sample(x, trailing):
    """Whether ``x`` is one sample that needs no conversion: the fast path of a call."""
    # ``is``: every native float64 array shares numpy's one float64 dtype; an
    # equal but distinct dtype object just takes the general path.
    return (type(x) is _NDARRAY and x.shape == trailing and x.dtype is _FLOAT64
            and x.flags.c_contiguous)


def call_unary(kernel, x, name, trailing, out_trailing, convention=None, batch_kernel=None):
    """
    Validate ``x``, run ``kernel(x, out[, convention])``, raise for a bad sample.

    ``out`` gets ``x``'s leading shape followed by ``out_trailing``; a 0-d
    result is returned as a scalar. ``convention`` is the Euler kernels'
    convention code (a named argument: unpacking ``*args`` costs ~50 ns of a
    ~1 us single-sample call). Large inputs go to ``batch_kernel`` (same
    signature) where one is given, and large batches are split across
    threads. A single float64 sample skips straight to the kernel, which
    checks its values.
    """
    if is_single_sample(x, trailing):
        out = new_array(out_trailing or _ONE)
        if convention is None:
            bad = kernel(x, out)
        else:
            bad = kernel(x, out, convention)
        if bad < 0:
            return out if out_trailing else out[0]
        a = x
    else:
        a = float_array(x, name, trailing)
        out = np.empty(a.shape[:a.ndim - len(trailing)] + out_trailing)
        args = () if convention is None else (convention,)
        if not is_batch(a, trailing):
            bad = kernel(a, out, *args)
        else:
            bad = _run(batch_kernel or kernel, (a,), (trailing,), out, out_trailing, args)
    if bad >= 0:
        raise_sample_error(bad, (name,), (a,), (trailing,))
    return out[()] if out.ndim == 0 else out


def call_binary(kernel, x, y, names, trailings, out_trailing, *args, batch_kernel=None):
    """
    Validate and broadcast ``x`` and ``y``, run ``kernel(x, y, out, *args)``, raise if bad.

    ``out`` gets the common leading shape followed by ``out_trailing``; large
    inputs go to ``batch_kernel`` where one is given, and large batches are
    split across threads; single float64 samples skip the checks that the
    kernel makes anyway.
    """
    scalar_y = trailings[1] == ()
    if scalar_y and (isinstance(y, float) or is_single_sample(y, ())):
        y = float(y)   # one scalar argument (an angle): kernels take ``np.asarray`` of it
    if is_single_sample(x, trailings[0]) and (
            type(y) is float if scalar_y else is_single_sample(y, trailings[1])):
        a, b = x, y
        out = new_array(out_trailing or _ONE)
        bad = kernel(*((a, b, out) + args))   # one tuple: cheaper than f(a, b, out, *args)
        if bad < 0:
            return out if out_trailing else out[0]
    else:
        a, b = broadcast_pair(float_array(x, names[0], trailings[0]),
                              float_array(y, names[1], trailings[1]), *trailings)
        out = np.empty(a.shape[:a.ndim - len(trailings[0])] + out_trailing)
        if not is_batch(a, trailings[0]):
            bad = kernel(a, b, out, *args)
        else:
            bad = _run(batch_kernel or kernel, (a, b), trailings, out, out_trailing, args)
    if bad >= 0:
        raise_sample_error(bad, names, (a, np.asarray(b)), trailings)
    return out[()] if out.ndim == 0 else out


def quaternion_product(p, q):
    """
    Hamilton product of two quaternions.

    Parameters
    ----------
    p, q : array_like, shape (..., 4)
        Quaternions (x, y, z, w); leading dimensions broadcast.

    Returns
    -------
    ndarray, shape (..., 4)
        ``p (x) q``: the rotation ``q`` followed by ``p`` (``R(p) R(q)``). Not
        normalised, so that the product of unit quaternions stays exact to
        rounding.

    Raises
    ------
    ValueError
        Wrong shape, a NaN/Inf component, or a zero quaternion.
    """
    return call_binary(_product_kernel, p, q, ('p', 'q'), ((4,), (4,)), (4,))


def quaternion_conjugate(q):
    """
    Conjugate ``(-x, -y, -z, w)``: the inverse rotation.

    Parameters
    ----------
    q : array_like, shape (..., 4)
        Quaternions (x, y, z, w).

    Returns
    -------
    ndarray, shape (..., 4)
        The conjugates (same norm as ``q``).
    """
    return call_unary(_conjugate_kernel, q, 'q', (4,), (4,))


def canonical_quaternion(q):
    """
    Unit quaternion with ``w >= 0`` representing the same rotation.

    Parameters
    ----------
    q : array_like, shape (..., 4)
        Quaternions (x, y, z, w), any non-zero norm (1e-160 to 1e+160 are fine).

    Returns
    -------
    ndarray, shape (..., 4)
        ``q / |q|`` with the sign chosen so that ``w > 0``; where ``w == 0``
        the first non-zero of x, y, z is positive. ``q`` and ``-q`` give the
        same result.
    """
    return call_unary(canonical_kernel, q, 'q', (4,), (4,))


def quaternion_distance(p, q):
    """
    Geodesic angle between the rotations of two quaternions.

    Parameters
    ----------
    p, q : array_like, shape (..., 4)
        Quaternions (x, y, z, w), any non-zero norm; leading dimensions broadcast.

    Returns
    -------
    ndarray, shape (...)
        ``2 atan2(|vec(p* q)|, |scalar(p* q)|)`` in [0, pi]: the angle of the
        rotation that takes ``p`` to ``q``. Accurate to ~1 ulp down to 0 (an
        ``acos`` form floors at ~1e-8). ``p`` and ``-p`` are the same rotation.
    """
    return call_binary(_distance_kernel, p, q, ('p', 'q'), ((4,), (4,)), ())


def rotate_vector(q, v):
    """
    Rotate vectors by quaternions: ``R(q) v``.

    Parameters
    ----------
    q : array_like, shape (..., 4)
        Quaternions (x, y, z, w), normalised internally.
    v : array_like, shape (..., 3)
        Vectors; leading dimensions broadcast with ``q``'s.

    Returns
    -------
    ndarray, shape (..., 3)
        The rotated vectors. With ``q`` body-to-world, this maps body
        coordinates to world coordinates (e.g. ``w_world = R w_body``).
    """
    return call_binary(_rotate_kernel, q, v, ('q', 'v'), ((4,), (3,)), (3,))
