"""``python -m d3cli`` is the ``d3stereo`` command."""

from .cli import main

if __name__ == "__main__":
    main(prog_name="d3stereo")
