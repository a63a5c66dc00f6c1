"""Start the simulator's child processes at the beginning of the session (see
tests/kernels/simulator_children.py) when their tests are selected."""

from __future__ import annotations

import os

import pytest

from tests.kernels import simulator_children


@pytest.hookimpl(trylast=True)  # after -m / -k have deselected what does not run
def pytest_collection_modifyitems(session, config, items):
    if os.environ.get("NUMBA_ENABLE_CUDASIM") == "1":  # inside a child: never start another
        return
    selected = {item.name for item in items}
    # the registering modules are imported by collection: CHILDREN is filled by now
    for name in list(simulator_children.CHILDREN):
        if name in selected:
            simulator_children.start(name)
