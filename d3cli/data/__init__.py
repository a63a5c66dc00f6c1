"""Data in and out: images, disparity files, masks, calibration, dataset layouts,
the synthetic road dataset and the bundled samples.

- ``io``: image / PFM / KITTI PNG / mask / calibration readers and atomic writers;
- ``datasets``: discovery of pairs in every supported layout and manifests, ground
  truth loading, disparity ranges;
- ``synth``: ray-cast synthetic road pairs with exact ground truth (``d3stereo synth``);
- ``samples/``: the bundled sample pairs (``d3stereo run`` without INPUT).

May import: :mod:`d3cli.config`, :mod:`d3cli.errors` only (no method, no batch).
"""
