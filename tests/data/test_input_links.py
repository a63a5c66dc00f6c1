"""An input that is a symlink loop or a broken link is named as such, not as a missing file."""

import pytest

from d3cli.data.layouts import discover
from d3cli.errors import InputError


def test_input_that_is_a_symlink_loop_is_named_as_one(tmp_path):
    loop = tmp_path / "loop"
    loop.symlink_to(loop)
    with pytest.raises(InputError, match=rf"^{loop}: a symlink loop \(the link leads back to itself\); "
                                         r"point it at the data or remove it$"):
        discover([loop])


def test_two_links_pointing_at_each_other(tmp_path):
    (tmp_path / "a").symlink_to(tmp_path / "b")
    (tmp_path / "b").symlink_to(tmp_path / "a")
    with pytest.raises(InputError, match=r"/a: a symlink loop"):
        discover([tmp_path / "a"])


def test_broken_link_names_its_target(tmp_path):
    link = tmp_path / "data"
    link.symlink_to(tmp_path / "gone")
    with pytest.raises(InputError, match=rf"^{link}: a broken symlink \(to {tmp_path / 'gone'}, which does not "
                                         r"exist\); fix the link or the path$"):
        discover([link])


def test_a_missing_path_is_still_a_wrong_path(tmp_path):
    with pytest.raises(InputError, match=r"nothing: no such file or folder; check the path$"):
        discover([tmp_path / "nothing"])
