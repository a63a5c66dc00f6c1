"""References of the road report's confidence evidence."""

from __future__ import annotations

import numpy as np
from scipy import ndimage


def ref_spikiness(depth, inside, peak_px, spike_px):
    """The definition: peak of depth over inside / peak of its spike_px median filter over inside."""
    filt = ndimage.median_filter(depth.astype(np.float64), size=spike_px, mode="nearest")
    top = np.sort(depth[inside])[-peak_px:].mean()
    return top / np.sort(filt[inside])[-peak_px:].mean()
