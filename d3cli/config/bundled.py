"""The presets: the configs that ship in the package (``configs/NAME.yaml`` of the checkout,
shipped in the wheel as ``d3cli/presets``), by name.  Imports nothing of the config package: the
loader and the checks both use it."""

from __future__ import annotations

import importlib.resources
import typing
from pathlib import Path

#: Package of the bundled configs, and their folder in it (a link to the checkout's
#: :data:`CHECKOUT_FOLDER`, whose files the wheel carries).
BUNDLED_PACKAGE = "d3cli"
BUNDLED_FOLDER = "presets"
#: The top-level folder of the configs in a source checkout.
CHECKOUT_FOLDER = "configs"


def bundled_configs() -> dict[str, Path]:
    """The configs that ship in the package, by name.

    Returns
    -------
    dict of str to Path
        ``{"default": .../d3cli/presets/default.yaml, "road": ..., ...}``, sorted by name
        (a Path when the package is installed as files, as pip installs it).
    """
    folder = importlib.resources.files(BUNDLED_PACKAGE) / BUNDLED_FOLDER
    found = {Path(entry.name).stem: entry for entry in folder.iterdir() if entry.name.endswith(".yaml")}
    return {name: typing.cast(Path, found[name]) for name in sorted(found)}
