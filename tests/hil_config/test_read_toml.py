"""read_toml: name or path lookup, and one exact line for each way a file can fail."""

import re

import pytest

from hil_config import read_toml


class ThingError(ValueError):
    pass


def _read(name_or_path, bundled_dir):
    return read_toml(name_or_path, bundled_dir, kind="thing", error=ThingError)


def test_a_name_is_looked_up_among_the_bundled_files_and_a_path_is_taken_as_is(tmp_path):
    bundled = tmp_path / "bundled"
    bundled.mkdir()
    (bundled / "alpha.toml").write_text("x = 1\n")
    other = tmp_path / "elsewhere.toml"
    other.write_text("y = 'two'\n")
    assert _read("alpha", bundled) == ({"x": 1}, bundled / "alpha.toml")
    assert _read(other, bundled) == ({"y": "two"}, other)
    assert _read(str(other), bundled) == ({"y": "two"}, other)


def test_a_missing_file_lists_the_bundled_names(tmp_path):
    for name in ("beta", "alpha"):
        (tmp_path / f"{name}.toml").write_text("")
    expected = f"{tmp_path / 'gamma.toml'}: no such thing file (bundled: alpha, beta)"
    with pytest.raises(ThingError, match=f"^{re.escape(expected)}$"):
        _read("gamma", tmp_path)


def test_unreadable_and_invalid_files_name_the_path_and_the_reason(tmp_path):
    not_utf8 = tmp_path / "latin1.toml"
    not_utf8.write_bytes("name = 'Ölberg'\n".encode("latin-1"))
    with pytest.raises(
        ThingError, match=rf"^{re.escape(str(not_utf8))}: cannot read \('utf-8' codec"
    ):
        _read(not_utf8, tmp_path)
    directory = tmp_path / "folder.toml"
    directory.mkdir()
    with pytest.raises(ThingError, match=rf"^{re.escape(str(directory))}: cannot read \(\[Errno"):
        _read(directory, tmp_path)
    broken = tmp_path / "broken.toml"
    broken.write_text("name = \n")
    expected = f"{broken}: not valid TOML (Invalid value (at line 1, column 8))"
    with pytest.raises(ThingError, match=f"^{re.escape(expected)}$"):
        _read(broken, tmp_path)
