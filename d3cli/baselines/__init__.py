"""Baseline stereo methods for side-by-side tables: OpenCV SGBM and PT-SGM, and the
optional peers ELAS and pandora census + SGM (``peers``, imported only when they run).

May import: :mod:`d3cli.method` (the result type, PT model and pyramid, so that PT-SGM
uses exactly PT-D3Stereo's transformation), of :mod:`d3cli.kernels` only the package,
:mod:`d3cli.kernels.backend` and the host facade :mod:`d3cli.kernels.host`, :mod:`d3cli.data`,
:mod:`d3cli.config`, :mod:`d3cli.errors`.  Each method's name, entry point and the config
section it is handed are declared in :data:`d3cli.config.methods.METHOD_SPECS`.
"""

from .peers import elas_disparity, pandora_sgm_disparity
from .pt_sgm import pt_sgm_disparity
from .sgbm import fill_holes_rowwise, sgbm_disparity

__all__ = ["elas_disparity", "fill_holes_rowwise", "pandora_sgm_disparity", "pt_sgm_disparity", "sgbm_disparity"]
