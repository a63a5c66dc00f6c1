"""Ctrl-C ends a ``d3stereo`` process with exit 130 and one line, whenever it comes:
while Python imports the libraries, and after a handled interrupt
whose KeyboardInterrupt passed through ``exec()``'d code (CPython then marks the process
to be killed by SIGINT after shutdown: status -2 instead of 130)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap

import pytest

RESUME = "Interrupted; rerun the same command to resume"


def _run_python(code: str, tmp_path) -> subprocess.CompletedProcess:
    """Run ``code`` as ``python -m`` runs d3cli: the module mode is the one where CPython
    turns its "unhandled KeyboardInterrupt" flag into death by SIGINT (``python -c`` and
    scripts exit through another path)."""
    (tmp_path / "inject_d3.py").write_text(textwrap.dedent(code))
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [os.getcwd(), os.environ.get("PYTHONPATH")]))}
    # Started as a terminal's foreground command is: with SIGINT at its default (a test run
    # started in the background of a non-interactive shell inherits SIGINT ignored).
    return subprocess.run([sys.executable, "-m", "inject_d3"], capture_output=True, text=True, env=env,
                          timeout=300, cwd=tmp_path,
                          preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))


@pytest.mark.parametrize("module", ["click", "numpy", "numba"])
def test_ctrl_c_while_importing_exits_130_with_one_line(tmp_path, make_pair_folder, module):
    """The interrupt lands while the command imports ``module``, inside exec()'d code as
    the standard library's dataclasses and namedtuple run it."""
    make_pair_folder(tmp_path / "pairs", "a")
    code = f"""
        import sys

        class Interrupting:  # a Ctrl-C at the moment {module!r} is imported
            def find_spec(self, name, path=None, target=None):
                if name == {module!r}:
                    exec("raise KeyboardInterrupt")
                return None

        sys.meta_path.insert(0, Interrupting())
        sys.argv = ["d3stereo", "run", "pairs", "-o", "out", "--method", "d3stereo", "-q"]
        from d3cli.__main__ import entry
        entry()
        """
    done = _run_python(code, tmp_path)
    assert done.returncode == 130, done.stderr
    assert done.stderr == RESUME + "\n"
    assert done.stdout == ""


def test_handled_interrupt_from_exec_code_in_the_batch_exits_130_not_by_the_signal(tmp_path, make_pair_folder):
    make_pair_folder(tmp_path / "pairs", "a")
    code = """
        import sys
        import d3cli.data.layouts as datasets

        def discover(inputs):  # Ctrl-C inside exec()'d code, as in a dataclass definition
            exec("raise KeyboardInterrupt")

        datasets.discover = discover
        sys.argv = ["d3stereo", "run", "pairs", "-o", "out", "--method", "sgbm"]
        from d3cli.__main__ import entry
        entry()
        """
    done = _run_python(code, tmp_path)
    assert done.returncode == 130, (done.returncode, done.stderr)  # was -2: killed by SIGINT after the line
    assert done.stderr == RESUME + "\n"


def test_ctrl_c_inside_a_kernel_during_the_jit_warm_up_is_an_interrupt(tmp_path, make_pair_folder):
    """A Ctrl-C inside a numba kernel before the first pair (the JIT warm-up) came out as a
    SystemError traceback with exit 1."""
    make_pair_folder(tmp_path / "pairs", "a")
    code = """
        import sys
        import d3cli.batch.dispatch as methods

        def compute_pair(*args, **kwargs):  # what numba raises when SIGINT lands in a kernel
            try:
                raise KeyboardInterrupt
            except KeyboardInterrupt:
                raise SystemError("CPUDispatcher(<function _diffuse>) returned a result with an exception set")

        methods.compute_pair = compute_pair
        sys.argv = ["d3stereo", "run", "pairs", "-o", "out", "--method", "d3stereo", "-q"]
        from d3cli.__main__ import entry
        entry()
        """
    done = _run_python(code, tmp_path)
    assert done.returncode == 130, done.stderr
    assert done.stderr == "Interrupted: 0 of 1 pair done; rerun the same command to resume\n"
    assert (tmp_path / "out" / "run.json").is_file() and not (tmp_path / "out" / ".d3stereo.lock").exists()



def test_sigterm_after_the_batch_exits_143_not_by_the_signal(tmp_path, make_pair_folder):
    """SIGTERM between the end of the batch and the exit (the summary lines): the batch's
    handler is gone, the run command's own ends it with 143 and the Terminated line (not
    death by the signal, -15, seen on a fast machine in test_adversarial), recorded in
    run.json."""
    import json

    make_pair_folder(tmp_path / "pairs", "a")
    code = """
        import os, signal, sys
        import click

        echo = click.echo

        def echo_then_sigterm(message=None, *args, **kwargs):
            if message is not None and str(message).startswith("sgbm:"):  # the counts: the batch has ended
                os.kill(os.getpid(), signal.SIGTERM)
            return echo(message, *args, **kwargs)

        click.echo = echo_then_sigterm
        sys.argv = ["d3stereo", "run", "pairs", "-o", "out", "--method", "sgbm"]
        from d3cli.__main__ import entry
        entry()
        """
    done = _run_python(code, tmp_path)
    assert done.returncode == 143, (done.returncode, done.stderr)
    assert done.stderr.strip().splitlines()[-1] == (
        "Terminated (SIGTERM): 1 of 1 pair done; rerun the same command to resume")
    run = json.loads((tmp_path / "out" / "run.json").read_text())
    # run.json agrees with the exit status (it said "not interrupted" beside exit 143)
    assert run["interrupted"] is True and run["n_failed"] == 0


def test_ctrl_c_after_the_batch_is_ignored(tmp_path, make_pair_folder):
    """SIGINT while the summary lines are printed, after run.json recorded the batch as
    complete: ignored, exit 0 (it gave 130 and "rerun the same command to resume" with
    nothing to resume; seen once in tests/batch/test_interrupts.py's eight moments)."""
    import json

    make_pair_folder(tmp_path / "pairs", "a")
    code = """
        import os, signal, sys
        import click

        echo = click.echo

        def echo_then_sigint(message=None, *args, **kwargs):
            if message is not None and str(message).startswith("sgbm:"):  # the counts: the batch has ended
                os.kill(os.getpid(), signal.SIGINT)
            return echo(message, *args, **kwargs)

        click.echo = echo_then_sigint
        sys.argv = ["d3stereo", "run", "pairs", "-o", "out", "--method", "sgbm"]
        from d3cli.__main__ import entry
        entry()
        """
    done = _run_python(code, tmp_path)
    assert done.returncode == 0, (done.returncode, done.stderr)
    assert "rerun" not in done.stderr
    run = json.loads((tmp_path / "out" / "run.json").read_text())
    assert run["interrupted"] is False and run["n_failed"] == 0


def test_sigterm_before_the_pairs_begin_exits_143(tmp_path, make_pair_folder):
    """SIGTERM while the batch takes its lock or starts its workers (after its SIGTERM
    handler is in place, before the pairs' loop wraps interrupts into BatchInterrupted).
    Failed before the CLI and the runner shared one Terminated class: the runner's had no
    ``terminated`` flag, so the command exited 130, as after Ctrl-C."""
    make_pair_folder(tmp_path / "pairs", "a")
    code = """
        import os, signal, sys
        import d3cli.batch.runner as runner

        make_executor = runner.make_executor

        def make_executor_then_sigterm(*args, **kwargs):
            os.kill(os.getpid(), signal.SIGTERM)  # lands in the runner's own handler
            return make_executor(*args, **kwargs)

        runner.make_executor = make_executor_then_sigterm
        sys.argv = ["d3stereo", "run", "pairs", "-o", "out", "--method", "sgbm"]
        from d3cli.__main__ import entry
        entry()
        """
    done = _run_python(code, tmp_path)
    assert done.returncode == 143, (done.returncode, done.stderr)
    assert done.stderr.strip().splitlines()[-1] == RESUME
    assert not (tmp_path / "out" / ".d3stereo.lock").exists()


def test_ctrl_c_during_the_kernel_warm_up_waits_for_it_then_exits_130(tmp_path, make_pair_folder):
    """A Ctrl-C while the kernels load (numba's cache is read through llvmlite ctypes
    callbacks: an interrupt raised inside one crashed the process, SIGSEGV) is held until
    the warm-up ends, then stops the batch with 130."""
    make_pair_folder(tmp_path / "pairs", "a")
    code = """
        import os, signal, sys, time
        import d3cli.batch.warmup as warmup

        def warm_jit(cfg, method):  # the warm-up, interrupted in its middle
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(0.3)
            open("warm-finished", "w").close()
            return 0.0

        warmup.warm_jit = warm_jit
        sys.argv = ["d3stereo", "run", "pairs", "-o", "out", "--method", "d3stereo", "-q"]
        from d3cli.__main__ import entry
        entry()
        """
    done = _run_python(code, tmp_path)
    assert done.returncode == 130, (done.returncode, done.stderr)
    assert (tmp_path / "warm-finished").exists()
    assert done.stderr.strip().splitlines()[-1].endswith("rerun the same command to resume")
