"""The road model, written once: the shift ``s(u, v)`` of the road plane, the restore of a
disparity matched against the warped right image, the rule "the match lies in the right
image" and the validity of a restored estimate (docs/design.md, 'Perspective
transformation').

Every user reads these functions: the perspective transformation's warp and restore (CPU
and CUDA drivers, through :func:`d3cli.kernels.ops.build_ops`), the finishing's road plane
and its validity after the restore and the right-image mask (host kernels, through
:data:`host`), and through those PT-D3Stereo, PT-SGM and the road report.  A shared
module of the kernels: it imports :mod:`d3cli.kernels.pixel` only, and every step may
import it.

The per-pixel rules follow :mod:`d3cli.kernels.pixel`: scalars in, scalars out, no
allocation, compiled by :func:`build` for any target.
"""

from __future__ import annotations

from types import SimpleNamespace

from numba import njit

from . import compile_cache as _compile_cache  # noqa: F401  (chooses the numba cache folder first)
from .pixel import INF

#: A match ``x = u - d`` lies in the right image when ``x >= -RIGHT_IMAGE_SLACK``: pixel
#: centres sit at integer columns and pixel 0 covers [-0.5, 0.5) (the pyramid's and the
#: uniqueness test's convention, where ``round(u - d)`` names the right pixel), so a
#: sub-pixel match in the left half of the first pixel is still seen by the right camera.
RIGHT_IMAGE_SLACK = 0.5


def build(jit):
    """``pt_shift, pt_restore_at, in_right_image, restore_drops`` compiled with ``jit``.

    Parameters
    ----------
    jit : callable
        A decorator such as ``numba.njit(cache=True)`` or ``numba.cuda.jit(device=True)``.

    Returns
    -------
    types.SimpleNamespace
    """

    @jit
    def pt_shift(a0, b1, b2, delta, v, u):
        """The road plane's shift ``s(u, v) = a0 + b1 v + b2 u - delta``, summed in that order.

        The road model ``d = a0 + a1 (v cos(theta) - u sin(theta))`` written linearly:
        ``b1 = a1 cos(theta)``, ``b2 = -a1 sin(theta)``; ``delta`` is the margin (0: the
        plane itself).  All in full-resolution pixels.
        """
        return a0 + b1 * v + b2 * u - delta

    @jit
    def pt_restore_at(d_prime, a0, b1, b2, delta, v, u):
        """Full-range disparity of a left pixel from its disparity ``d_prime`` against the
        warped right image.

        Left (u, v) matches ``R'(u - d', v) = R(u - d' - s(u - d', v), v)``, so
        ``d = d' + s(u - d', v) = d' (1 - b2) + s(u, v)``; inf stays inf.
        """
        if not d_prime < INF:
            return INF
        return d_prime * (1.0 - b2) + pt_shift(a0, b1, b2, delta, v, u)

    @jit
    def in_right_image(u, d):
        """Whether the match ``u - d`` of left column ``u`` lies in the right image
        (:data:`RIGHT_IMAGE_SLACK`); False for a NaN or +inf disparity.

        The verdict is the same in float32 and in float64 for a float32 ``d`` (near the
        bound ``u - d`` is exact in both), so callers may subtract in either.
        """
        return u - d >= -RIGHT_IMAGE_SLACK

    @jit
    def restore_drops(valid, narrow, restored, u, hi):
        """Why a restored estimate becomes a hole: ``(ends, outside, negative)``, each
        False where ``valid`` is.

        ``ends``: the narrow-range disparity at either end of the narrow range
        (``narrow <= 0`` or ``narrow >= hi``: the true match lies outside the band);
        ``outside``: the restored match is not in the right image (:func:`in_right_image`);
        ``negative``: the restored disparity is not ``>= 0`` (NaN included).  The estimate
        is kept when none holds.  Bitwise ``&``, ``|`` of bools: selects, no branches.
        """
        ends = valid & ((narrow <= 0) | (narrow >= hi))
        outside = valid & (not in_right_image(u, restored))
        negative = valid & (not (restored >= 0))
        return ends, outside, negative

    return SimpleNamespace(pt_shift=pt_shift, pt_restore_at=pt_restore_at, in_right_image=in_right_image,
                           restore_drops=restore_drops)


#: The road model compiled for the host kernels (``finishing/``), inlined into their loops.
host = build(njit(cache=True, inline="always"))
