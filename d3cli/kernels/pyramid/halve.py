"""The 2x2 area average that makes each pyramid level from the one above it.

:func:`halve_area` gives the bytes of NumPy's
``(0.25 * (a[0::2, 0::2] + a[1::2, 0::2] + a[0::2, 1::2] + a[1::2, 1::2])).astype(np.float32)``
on a float32 image: the same three float32 additions in the same order, then the float32
product with 0.25 (NumPy 2 keeps a Python float scalar at the array's precision).  In NumPy
the four strided views and three temporaries take about 1.2 ms per 720p pyramid, three
pyramids per road pair; the kernel about a tenth of that (docs/performance.md).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..pool import row_tasks, run_tasks
from .pixel import build

_halve_at = build(njit(cache=True, nogil=True)).halve_at


@njit(cache=True, nogil=True)
def halve_task(task, tasks, img, out):
    h, w = out.shape
    y0, y1 = (task * h) // tasks, ((task + 1) * h) // tasks
    for y in range(y0, y1):
        top = img[2 * y]
        bottom = img[2 * y + 1]
        row = out[y]
        for x in range(w):
            row[x] = _halve_at(top, bottom, x)  # the reference's order (pixel.py)


def halve_area(img: np.ndarray) -> np.ndarray:
    """The 2x2 area average of a float32 image, ``(H // 2, W // 2)`` (an odd last row or
    column dropped); a new C-contiguous float32 array.

    Parameters
    ----------
    img : ndarray, float32, (H, W)
        Any strides; converted to a contiguous float32 array first where it is not one.
    """
    img = np.ascontiguousarray(img, dtype=np.float32)
    out = np.empty((img.shape[0] // 2, img.shape[1] // 2), np.float32)
    if out.size:
        run_tasks(halve_task, row_tasks(out.shape[0]), img, out)
    return out


#: The compiled kernels of this module (nogil, cached on disk), run by :func:`d3cli.kernels.pool.run_tasks`.
KERNELS = (halve_task,)
