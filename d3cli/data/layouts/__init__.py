"""Dataset layouts -> a sorted list of :class:`Pair` records, and loading a pair.

:func:`discover` takes folders, manifest YAMLs or two image files and auto-detects each
layout.  No image is read while discovering (only small text files: ``SOURCE.txt``,
``calib.txt``, manifests), so a large dataset is listed in milliseconds; images and
ground truth are read later by :func:`load_pair_images` and :func:`load_ground_truth`.

Layouts (``layout:`` name in a manifest, then what is expected on disk):

``pair-folders``
    A folder of pair folders, the layout of the Middlebury/KITTI development data.  Each pair folder holds
    ``left.<ext>`` and ``right.<ext>`` (png, jpg, ppm, pgm, tif, bmp), optionally
    ``disp_gt.<pfm|png|pgm|npy>``, a non-occlusion mask (``mask0nocc.png``,
    ``disp_gt_nocc.png``, ``nonocc.png``, ``mask_nonocc.png`` or KITTI's ``disp_noc.png``), ``calib.txt`` and a
    ``SOURCE.txt`` whose machine-readable lines ``gt_scale: 256``, ``gt_invalid: 0``
    (``0``, ``inf``, ``auto`` or ``none``; the first word counts), optionally
    ``max_disparity: N``, ``family: NAME`` and ``image_size: WxH`` are used.
    The pair name is the folder name; the family is the name's prefix before the first
    ``-`` (``middlebury2014-teddy-Q`` -> ``middlebury2014``), with the road sequences
    ``karlsruhe2010-*`` and ``sid-*`` mapped to ``road``.  The max disparity is
    ``ndisp`` of ``calib.txt`` when present, rescaled by ``image width / calib width``
    when ``SOURCE.txt`` gives an ``image_size`` that differs from the calib's ``width``
    (images downsized after calibration); otherwise None.
``pair``
    One such pair folder given directly.
``middlebury2014``
    MiddEval3: a root holding ``trainingQ``/``trainingH``/``trainingF`` (and/or
    ``testQ``/...), one of those folders, or one scene folder.  A scene folder holds
    ``im0.png``, ``im1.png``, ``calib.txt`` (``ndisp`` -> max disparity) and, once the
    ``MiddEval3-GT0-*.zip`` archives are unpacked over it, ``disp0GT.pfm`` and
    ``mask0nocc.png`` (255 = non-occluded; 128 = occluded is *not* evaluated).
    Names: ``middlebury2014-<scene lower case>-<Q|H|F>``.
``kitti2012``
    ``<root>/training`` and/or ``<root>/testing`` (or a split folder itself) with
    ``colored_0``/``colored_1`` (preferred when present) or ``image_0``/``image_1``,
    ``disp_occ`` (ground truth, all pixels), ``disp_noc`` (used as the non-occlusion
    mask) and ``calib/<frame>.txt``; only the ``*_10.png`` frames are stereo pairs.
    Names: ``kitti2012-000000_10`` (``kitti2012-testing-...`` for the test split).
``kitti2015``
    The same with ``image_2``/``image_3``, ``disp_occ_0``, ``disp_noc_0`` and
    ``calib_cam_to_cam/<frame>.txt``.  Names ``kitti2015-000000_10``.
``udtiri-stereo``
    Assumed layout (UDTIRI-Stereo as released by its authors): a root, or split
    sub-folders of it (``train``/``val``/``test``...), each with ``left/``, ``right/``
    and ``disparity_noc/`` folders of files with matching stems; left/right are images,
    ground truth is ``<stem>.npy`` (float32 disparity in pixels; non-finite or <= 0 =
    invalid; a ``<stem>.pfm`` is accepted too).  Names
    ``udtiri-[<split>-]<stem>``, family ``udtiri``.
``stereo-road``
    Assumed layout (Stereo-Road, Fan et al. 2018, University of Bristol): a root, or
    split sub-folders of it, with ``left/`` and ``right/`` (or ``image_L/`` and
    ``image_R/``) folders of PNGs with matching names and no ground truth; an optional
    ``calib.txt`` beside them (or in the root) applies to every pair, and
    ``calib/<stem>.txt`` to one pair.  Names ``stereo-road-[<split>-]<stem>``, family
    ``road``.
manifest YAML
    See ``data_manifests/README.md``: ``root:`` (relative to the manifest), an optional
    ``layout:`` expanded at the root, a ``pairs:`` list of {name, left, right, gt,
    gt_scale, gt_invalid, nocc, calib, max_disparity, family}, and optional top-level
    defaults (``gt_scale``, ``gt_invalid``, ``family``, ``max_disparity``).
two image files
    ``left right``: one pair named after the left file (or its folder when the file is
    called ``left``/``im0``), without ground truth.

Modules: ``pair`` (the record, names), ``files`` (folder scanning), ``folders``,
``middlebury``, ``kitti``, ``road`` (one per layout), ``detect`` (layout detection),
``manifest``, ``discover``, ``loading``; this package re-exports their public names.

May import: :mod:`d3cli.data.formats`, :mod:`d3cli.config`, :mod:`d3cli.errors` only
(no synth, no method, no batch).
"""

from __future__ import annotations

from .pair import (DEFAULT_KEYS, GT_NAMES, LAYOUTS, MANIFEST_EXTENSIONS, MANIFEST_KEYS, NOCC_NAMES, PAIR_KEYS,
                   ROAD_PREFIXES, Pair, family_from_name, safe_name)
from .folders import read_pair_folder
from .detect import detect_layout, expand_layout
from .manifest import load_manifest
from .discover import discover
from .loading import load_ground_truth, load_pair_images, normalise_bit_depth, pair_image_size, resolve_max_disparity

__all__ = [
    "DEFAULT_KEYS", "GT_NAMES", "LAYOUTS", "MANIFEST_EXTENSIONS", "MANIFEST_KEYS", "NOCC_NAMES", "PAIR_KEYS",
    "ROAD_PREFIXES", "Pair", "detect_layout", "discover", "expand_layout", "family_from_name", "load_ground_truth",
    "load_manifest", "load_pair_images", "normalise_bit_depth", "pair_image_size", "read_pair_folder",
    "resolve_max_disparity", "safe_name",
]
