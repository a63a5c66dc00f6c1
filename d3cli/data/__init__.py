"""Data in and out: file formats, dataset layouts, the synthetic road dataset and the
bundled samples.

- ``formats``: image / PFM / KITTI PNG / disparity / mask / calibration readers, the
  colour picture of a disparity map, and the atomic writer every output goes through;
- ``layouts``: discovery of pairs in every supported layout and manifests, ground
  truth loading, disparity ranges;
- ``synth``: ray-cast synthetic road pairs with exact ground truth (``d3stereo synth``);
- ``legend``: text, colour bars and legends of every picture (letters >= 12 px, titles
  with units);
- ``samples/``: the bundled sample pairs (``d3stereo run`` without INPUT).

Inside: ``formats`` imports nothing else of ``data``; ``layouts`` and ``synth`` import
``formats``; neither imports the other.

May import: :mod:`d3cli.config`, :mod:`d3cli.errors` only (no method, no batch).
"""
