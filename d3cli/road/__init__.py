"""Road outputs derived from a disparity map: point clouds (and, next, road-surface
height maps and defects).

May import: :mod:`d3cli.data`, :mod:`d3cli.config`, :mod:`d3cli.errors` (and the PT
road model of :mod:`d3cli.method.perspective`).  Never the batch or the CLI.
"""
