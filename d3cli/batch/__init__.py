"""Running many pairs: discovery results in, one output folder out.

- ``runner``: :func:`run_batch` (``d3stereo run``), resume, interruption;
- ``records``: :class:`BatchResult` and ``run.json``;
- ``signals``: Ctrl-C and SIGTERM held, deferred or turned into an interrupt during a batch;
- ``extras``: ``cloud.ply`` and the road outputs of a complete pair, from its files;
- ``dispatch``: runs a method by its name (:func:`compute_pair`), from its declaration in
  :data:`d3cli.config.methods.METHOD_SPECS`;
- ``scoring``: scoring a pair or folders of predictions (``d3stereo eval``);
- ``outputs``: the per-pair files, written atomically, read back, removed;
- ``fingerprint``: what a stored result depends on (resume decisions), versions;
- ``lock``: one writer per output folder (a run or an eval), or the shards of one batch together;
- ``executors/``: where pairs run, one module per executor behind one ``Executor``
  protocol (``base``, with ``--workers`` and ``--shard``): ``local`` (here, one pair
  after the other), ``pooled`` (a local process pool), ``pipelined`` (one process,
  reading ahead and writing behind the pair computing), ``cluster`` (Dask,
  ``--scheduler``, its scheduler probe); :func:`~d3cli.batch.executors.make_executor`
  picks one;
- ``staging``: a pair's folder written aside and renamed into place; file records checked on resume;
- ``steps``: a pair's steps, so that an internal error names the step;
- ``warmup``: compiling the numba kernels once before the first pair;
- ``resources``: the memory check before a pair is computed.

May import everything below it: method, baselines, evaluation, road, kernels, data,
config, errors.  Only :mod:`d3cli.cli` imports this package.
"""

from .executors import SCHEDULER_ENV, parse_prefetch, parse_shard, parse_workers, select_shard
from .scoring import evaluate_folders, evaluate_predictions
from .fingerprint import package_versions, settings_fingerprint
from .lock import LOCK_FILE, acquire_lock, ensure_writable, release_lock
from .dispatch import compute_pair
from .outputs import OUTPUT_FILES, RESULT_FILE, RUN_FILE
from .runner import BatchInterrupted, BatchResult, run_batch
from .signals import terminate_after_batch

__all__ = [
    "BatchInterrupted",
    "BatchResult",
    "LOCK_FILE",
    "OUTPUT_FILES",
    "RESULT_FILE",
    "RUN_FILE",
    "SCHEDULER_ENV",
    "acquire_lock",
    "compute_pair",
    "ensure_writable",
    "evaluate_folders",
    "evaluate_predictions",
    "package_versions",
    "parse_prefetch",
    "parse_shard",
    "parse_workers",
    "release_lock",
    "run_batch",
    "select_shard",
    "settings_fingerprint",
    "terminate_after_batch",
]
