"""The real flight logs carried with the project are the verbatim published files."""

import hashlib

import pytest

from conftest import QUAD4001_LOG, X500_LOG


@pytest.mark.parametrize(
    ("path", "sha256"),
    [
        (X500_LOG, "afbc74c60284a7e243aa4d6e5e836b814145b86ac52b02df4a1997d4263d6d61"),
        (QUAD4001_LOG, "93dfd1f09642a556917a8a6da0b888e79df39f9c5d8518044e6e5d3aed22d86a"),
    ],
)
def test_flight_log_is_verbatim_copy(path, sha256):
    assert hashlib.sha256(path.read_bytes()).hexdigest() == sha256
