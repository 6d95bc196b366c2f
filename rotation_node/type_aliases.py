"""
Type aliases of the public API: arrays, scalar tuples and file paths.

Inputs are anything numpy turns into an array (``ArrayLike``): lists,
tuples, scalars, arrays of any dtype and layout. Results are float64 arrays;
a function whose result for one sample has shape ``()`` returns a numpy
float64 scalar for a single sample and an array for several.
"""
import os
from typing import Union

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ['ArrayLike', 'FloatArray', 'FloatArrayOrScalar', 'IntArray', 'BoolArray',
           'Quaternion4', 'Vector3', 'Matrix9', 'StrPath']

#: A float64 array: the result of every conversion.
FloatArray = NDArray[np.float64]
#: A float64 array, or one float64 scalar where the result has shape ``()``.
FloatArrayOrScalar = Union[NDArray[np.float64], np.float64]
#: An int64 array (e.g. nanosecond stamps).
IntArray = NDArray[np.int64]
#: A boolean array (e.g. per-sample flags).
BoolArray = NDArray[np.bool_]
#: One quaternion (x, y, z, w) as four floats: the compiled scalar formulas' values.
Quaternion4 = tuple[float, float, float, float]
#: One 3-vector as three floats.
Vector3 = tuple[float, float, float]
#: One 3 x 3 matrix as nine floats, row-major.
Matrix9 = tuple[float, float, float, float, float, float, float, float, float]
#: A file path as the caller gives it: text or a path object.
StrPath = Union[str, os.PathLike[str]]
