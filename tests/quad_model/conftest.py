"""Fixtures for the quad_model tests: bundled vehicles and idealized variants of them."""

import dataclasses

import numpy as np
import pytest

from quad_model import Vehicle, load_vehicle


def _variant(vehicle: Vehicle, **sections: dict) -> Vehicle:
    """A copy of ``vehicle`` with some parameters replaced, e.g. ``body={"mass_kg": 2.0}``."""
    changes = {
        name: dataclasses.replace(getattr(vehicle, name), **values)
        for name, values in sections.items()
    }
    return dataclasses.replace(vehicle, **changes)


@pytest.fixture(scope="session")
def variant():
    """``variant(vehicle, section={key: value})``: a vehicle with some parameters replaced."""
    return _variant


@pytest.fixture(scope="session")
def f450() -> Vehicle:
    return load_vehicle("f450_high_precision")


@pytest.fixture(scope="session")
def x500() -> Vehicle:
    return load_vehicle("x500_v2")


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20240601)


@pytest.fixture(scope="session")
def f450_no_drag(f450: Vehicle) -> Vehicle:
    """The F450 without aerodynamic drag: closed-form rigid-body cases."""
    return _variant(
        f450,
        body={"drag_area_m2": (0.0, 0.0, 0.0), "angular_drag_nms2": (0.0, 0.0, 0.0)},
        propulsion={"rotor_drag_coefficient_ns_per_m_rad": 0.0},
    )
