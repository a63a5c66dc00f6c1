"""The road survey on a map: where each frame was taken (``positions``: ``track.csv``, a GPX
track or the left images' EXIF GPS tags), where each defect lies on the earth
(``geolocate``: pixel rays onto the frame's fitted road plane, then a geodesic step from
the frame's fix), one defect for the sightings of the same pothole in overlapping frames
(``merge``) and the files of the map (``outputs``: ``OUT/defects.geojson``,
``OUT/track.geojson``, the track's length in ``OUT/road_survey.json``).  pyproj and
shapely (the ``gis`` extra) are imported only where a track is used (``gis``).

May import: :mod:`d3cli.road` (its file readers and the camera), :mod:`d3cli.data`,
:mod:`d3cli.config`, :mod:`d3cli.errors`.  Never the batch or the CLI.
"""

from .outputs import MAP_FILES, check_positions, survey_map

__all__ = ["MAP_FILES", "check_positions", "survey_map"]
