"""The real flight logs carried with the project are the verbatim published files."""

import hashlib

import pytest


@pytest.mark.parametrize(
    ("fixture", "sha256"),
    [
        ("x500_log", "afbc74c60284a7e243aa4d6e5e836b814145b86ac52b02df4a1997d4263d6d61"),
        ("quad4001_log", "93dfd1f09642a556917a8a6da0b888e79df39f9c5d8518044e6e5d3aed22d86a"),
    ],
)
def test_flight_log_is_verbatim_copy(request, fixture, sha256):
    path = request.getfixturevalue(fixture)
    assert hashlib.sha256(path.read_bytes()).hexdigest() == sha256
