"""CUDA driver of the pyramid: the image uploaded once in its own dtype, converted to
float32 and halved on the device (``pixel.halve_at``, the CPU's expression)."""

from __future__ import annotations

import numpy as np
from numba import cuda

from ..cuda_launch import is_device, on_device, per_pixel
from .pixel import build

_halve_at = build(cuda.jit(device=True)).halve_at

#: Image dtypes uploaded as they are (converted to float32 on the device).
DEVICE_DTYPES = (np.uint8, np.float32)


@cuda.jit(cache=True)
def _to_float32(img, out):
    u, v = cuda.grid(2)
    if v < out.shape[0] and u < out.shape[1]:
        out[v, u] = np.float32(img[v, u])


@cuda.jit(cache=True)
def _halve(img, out):
    u, v = cuda.grid(2)
    if v < out.shape[0] and u < out.shape[1]:
        out[v, u] = _halve_at(img[2 * v], img[2 * v + 1], u)


def pyramid(image, levels):
    """Grey pyramid of a uint8 or float32 (H, W) image, finest first (float32 device arrays).

    A host image is uploaded once in its own dtype (uint8: a quarter of the float32
    bytes; another dtype is converted to float32 on the host first).
    The contract (arguments, shapes, results): :meth:`d3cli.kernels.backend.Backend.pyramid`.
    """
    if not is_device(image):
        image = np.asarray(image)
        if image.dtype not in DEVICE_DTYPES:
            image = image.astype(np.float32)
    d_image = on_device(image)
    if d_image.dtype != np.float32:
        d_image = per_pixel(_to_float32, d_image.shape, np.float32, d_image)
    out = [d_image]
    for _ in range(int(levels) - 1):
        h, w = out[-1].shape
        out.append(per_pixel(_halve, (h // 2, w // 2), np.float32, out[-1]))
    return out
