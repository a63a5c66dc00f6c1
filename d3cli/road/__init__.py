"""Road outputs derived from a disparity map: point clouds (``pointcloud``), the robust road
plane and heights above it (``plane``), potholes and bumps measured in 3-D (``defects``,
cut apart by ``splitting``, re-matched with a small window by ``rematch``), whether each
can be trusted and why not (``confidence``), their ASTM D6433 severity (``severity``), the
labelled picture (``overlay``) and the files of ``--road-report`` (``outputs``), which
finds and measures the defects on the coarser grid of ``grid``; the
compiled loops they share are in ``compiled``, the masks' morphology in ``morphology`` and
the second thread the report hands independent work to in ``threads``.

May import: :mod:`d3cli.data`, :mod:`d3cli.config`, :mod:`d3cli.errors` (and the PT
road model of :mod:`d3cli.method.perspective`).  Never the batch or the CLI.
"""
