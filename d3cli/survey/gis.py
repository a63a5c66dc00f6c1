"""The optional GIS libraries of the map (the ``gis`` extra: pyproj, shapely), imported on use.

Without them d3stereo runs as usual; only a track (or EXIF positions) asks for them, and
then :func:`require_gis` says how to install them in one line.
"""

from __future__ import annotations

import functools
import importlib.util

from ..config import INSTALL_GIS as INSTALL
from ..errors import InputError, where_what_fix


def have_gis() -> bool:
    """True when pyproj and shapely can be imported."""
    return all(importlib.util.find_spec(name) is not None for name in ("pyproj", "shapely"))


def require_gis(where: str) -> None:
    """Raise :class:`~d3cli.errors.InputError` naming ``where`` (the track) when pyproj or
    shapely is missing: ``<where>: a map of the defects needs pyproj and shapely, which are
    not installed; install them with pip install "d3stereo[gis]"``."""
    if not have_gis():
        raise InputError(where_what_fix(where, "a map of the defects needs pyproj and shapely, which are not installed",
                                        f"install them with {INSTALL}"))


@functools.lru_cache(maxsize=1)
def geod():
    """The WGS84 ellipsoid's :class:`pyproj.Geod` (geodesic distances, azimuths, steps)."""
    from pyproj import Geod

    return Geod(ellps="WGS84")


def local_projection(lat0: float, lon0: float):
    """(forward, inverse) functions between lon/lat degrees and metres east/north of an
    azimuthal equidistant projection centred on (lat0, lon0): a local metric plane where
    distances from the centre are exact and, within a few km, every distance is true to
    better than 1 part in 10^5."""
    from pyproj import Transformer

    crs = f"+proj=aeqd +lat_0={lat0:.9f} +lon_0={lon0:.9f} +datum=WGS84 +units=m +no_defs"
    to_xy = Transformer.from_crs("EPSG:4326", crs, always_xy=True)
    to_ll = Transformer.from_crs(crs, "EPSG:4326", always_xy=True)
    return to_xy.transform, to_ll.transform
