"""d3stereo: decisive disparity diffusion (D3Stereo) stereo matching and a batch evaluator.

Python entry points::

    from d3cli import D3Stereo, load_config
    result = D3Stereo(load_config()).compute(left, right, max_disparity=64)
    result.disparity  # float32 (H, W), inf where invalid when filling is off
"""

#: The release, the one place it is written (pyproject.toml reads it; CHANGELOG.md names it).
__version__ = "1.0.0"

from .errors import BackendUnavailable, ConfigError, D3Error, InputError, OutputError  # noqa: E402


def __getattr__(name):
    # The pipeline pulls in numba; import it lazily so `d3stereo info` and the config
    # checks stay fast.  The config (PyYAML) is lazy too: `d3stereo` imports this package
    # before its Ctrl-C guard (d3cli.__main__.entry) is in place, so it must be quick.
    if name in ("D3Stereo", "DisparityResult"):
        from . import method

        return getattr(method, name)
    if name in ("Config", "load_config"):
        from . import config

        return getattr(config, name)
    raise AttributeError(name)


__all__ = [
    "Config",
    "load_config",
    "D3Stereo",
    "DisparityResult",
    "D3Error",
    "ConfigError",
    "InputError",
    "BackendUnavailable",
    "OutputError",
    "__version__",
]
