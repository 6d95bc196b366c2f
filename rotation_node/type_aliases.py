"""
Type aliases of the public API: arrays, scalar tuples and file paths (docs/typing.md).

Inputs are anything numpy turns into an array (``ArrayLike``); results are float64 arrays, or
a float64 scalar for a single sample whose result has shape ``()``.
"""
import os
from typing import Union

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ['ArrayLike', 'FloatArray', 'FloatArrayOrScalar', 'IntArray', 'BoolArray',
           'Quaternion4', 'Vector3', 'Matrix9', 'StrPath']

FloatArray = NDArray[np.float64]
#: A float64 array, or one float64 scalar where the result has shape ``()``.
FloatArrayOrScalar = Union[NDArray[np.float64], np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]
#: One quaternion (x, y, z, w) as four floats: the compiled scalar formulas' values.
Quaternion4 = tuple[float, float, float, float]
Vector3 = tuple[float, float, float]
#: One 3 x 3 matrix as nine floats, row-major.
Matrix9 = tuple[float, float, float, float, float, float, float, float, float]
StrPath = Union[str, os.PathLike[str]]
