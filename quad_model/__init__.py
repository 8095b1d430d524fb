"""Vehicle and sensor physics of a multicopter at 5 kHz: pure numerics, no I/O.

Typical use (what the rig does every 1 ms autopilot frame)::

    import numpy as np
    from quad_model import QuadModel, SensorSuite, load_vehicle

    rng = np.random.default_rng(7)
    vehicle = load_vehicle("f450_high_precision")
    model = QuadModel(vehicle, rng)
    sensors = SensorSuite(vehicle, model.environment, rng)
    model.advance([0.6, 0.6, 0.6, 0.6], 0.001)   # 5 RK4 substeps, one compiled call
    readings = sensors.sample(model.truth)        # IMU / mag / baro / GPS when due
"""

from quad_model.environment import Environment, GeoPoint, MagneticField, Wind
from quad_model.model import ModelInputError, Mount, QuadBatch, QuadModel, VehicleTruth
from quad_model.sensors import (
    BaroSample,
    GpsSample,
    ImuSample,
    MagSample,
    SensorReadings,
    SensorSuite,
)
from quad_model.vehicle import Vehicle, VehicleFileError, load_vehicle

__all__ = [
    "BaroSample",
    "Environment",
    "GeoPoint",
    "GpsSample",
    "ImuSample",
    "MagSample",
    "MagneticField",
    "ModelInputError",
    "Mount",
    "QuadBatch",
    "QuadModel",
    "SensorReadings",
    "SensorSuite",
    "Vehicle",
    "VehicleFileError",
    "VehicleTruth",
    "Wind",
    "load_vehicle",
]
