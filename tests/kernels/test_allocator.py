"""kernels/allocator.py: freed volumes stay in the heap (no page faults on reuse)."""

import os
import subprocess
import sys

import pytest

PROBE = """
import resource, numpy as np
import d3cli.kernels as k
from d3cli.kernels import allocator
np._core.multiarray._set_madvise_hugepage(False)  # 4 KB pages: one fault per page touched
a = np.ones(8 << 20)      # 64 MB, freed at once
del a
before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
b = np.ones(8 << 20)      # the same size again
print(allocator.keep_freed_memory(), resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before)
"""


def _probe(**env):
    full = dict(os.environ)
    for key in ("D3STEREO_MALLOC", "MALLOC_MMAP_THRESHOLD_", "MALLOC_TRIM_THRESHOLD_"):
        full.pop(key, None)
    full.update(env)
    out = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True, env=full, check=True)
    kept, faults = out.stdout.split()
    return kept == "True", int(faults)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's mallopt")
def test_a_freed_volume_is_reused_without_page_faults():
    kept, faults = _probe()
    assert kept
    # 64 MB are 16384 pages of 4 KB: reused from the heap they fault (almost) none
    assert faults < 1000


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's mallopt")
@pytest.mark.parametrize("env", [{"D3STEREO_MALLOC": "system"}, {"MALLOC_TRIM_THRESHOLD_": "131072"}])
def test_the_opt_out_and_the_users_own_settings_keep_glibcs_defaults(env):
    kept, faults = _probe(**env)
    assert not kept
    assert faults > 10000  # munmap'ed and faulted in again, page by page
