"""The fault injector: start/end times, the layer each fault acts on, seeded noise."""

import numpy as np
import pytest

from quad_model.sensors import BaroSample, ImuSample, SensorReadings
from rig.chips.layer import ChipFault
from rig.errors import ScenarioError
from rig.scenarios.faults import FaultInjector, check_motors
from rig.scenarios.scenario import (
    BusBitFlip,
    ChipMute,
    MotorDegradation,
    MotorLoss,
    NoiseBurst,
    PwmDropout,
    SensorStuck,
)


class RecordingModel:
    """Stands in for QuadModel's motor-health hook, recording each call."""

    def __init__(self):
        self.calls = []

    def set_motor_health(self, motor, thrust_fraction):
        self.calls.append((motor, thrust_fraction))


def readings(t, accel=(0.0, 0.0, -9.81), pressure=95_000.0):
    imu = ImuSample(t, np.array(accel), np.zeros(3), 25.0)
    return SensorReadings(imu=imu, mag=None, baro=BaroSample(t, pressure, 20.0), gps=None)


def make(*faults, seed=0, motors=4):
    events = []
    injector = FaultInjector(
        faults, np.random.default_rng(seed), lambda t, text: events.append((t, text)), motors
    )
    return injector, events


def test_motor_faults_act_on_the_model_and_are_announced():
    injector, events = make(
        MotorDegradation(start_s=1.0, end_s=2.0, motor=2, efficiency=0.6),
        MotorLoss(start_s=1.5, motor=0),
    )
    model = RecordingModel()
    for time_us in (500_000, 1_000_000, 1_500_000, 2_000_000, 3_000_000):
        injector.update(time_us, model)
    assert model.calls == [(2, 0.6), (0, 0.0), (2, 1.0)]
    assert events == [
        (1_000_000, "fault motor_degradation (motor=2, efficiency=0.6) started"),
        (1_500_000, "fault motor_loss (motor=0) started"),
        (2_000_000, "fault motor_degradation (motor=2, efficiency=0.6) ended"),
    ]


def test_noise_burst_has_the_configured_std_and_is_seeded():
    def burst(seed):
        injector, _ = make(NoiseBurst(start_s=0.0, sensor="accel", std=2.0),
                           seed=seed)  # fmt: skip
        injector.update(0, RecordingModel())
        return np.array([injector.samples(readings(0.0)).imu.accel_mps2 for _ in range(4000)])

    values = burst(1)
    assert values.std(axis=0) == pytest.approx([2.0, 2.0, 2.0], rel=0.05)  # 4000 draws: ±3 %
    assert values.mean(axis=0) == pytest.approx([0.0, 0.0, -9.81], abs=0.1)
    np.testing.assert_array_equal(values, burst(1))
    assert not np.array_equal(values, burst(2))


def test_stuck_sensor_repeats_its_last_healthy_value_then_recovers():
    injector, _ = make(SensorStuck(start_s=1.0, end_s=2.0, sensor="baro"))
    model = RecordingModel()
    injector.update(500_000, model)
    assert injector.samples(readings(0.5, pressure=95_000.0)).baro.pressure_pa == 95_000.0
    injector.update(1_000_000, model)
    assert injector.samples(readings(1.0, pressure=94_000.0)).baro.pressure_pa == 95_000.0
    injector.update(2_000_000, model)
    assert injector.samples(readings(2.0, pressure=93_000.0)).baro.pressure_pa == 93_000.0


def test_bus_and_pwm_faults_map_to_chip_inputs_and_channels():
    injector, _ = make(
        BusBitFlip(start_s=0.0, chip="mpu6000", mask=0x01),
        BusBitFlip(start_s=0.0, chip="mpu6000", mask=0x80),
        ChipMute(start_s=0.0, chip="ms5611"),
        PwmDropout(start_s=0.0, channel=3),
    )
    injector.update(0, RecordingModel())
    assert injector.chip_faults() == {
        "mpu6000": ChipFault(mute=False, flip=0x81), "ms5611": ChipFault(mute=True, flip=0),
    }  # fmt: skip
    assert injector.pwm_dropped() == {3}
    everything, _ = make(PwmDropout(start_s=0.0))
    everything.update(0, RecordingModel())
    assert everything.pwm_dropped() == {0, 1, 2, 3}


def test_an_octo_has_eight_motors_to_fault_and_to_drop_out():
    injector, _ = make(MotorLoss(start_s=1.0, motor=7), PwmDropout(start_s=2.0), motors=8)
    model = RecordingModel()
    for time_us in (1_000_000, 2_000_000):
        injector.update(time_us, model)
    assert model.calls == [(7, 0.0)]
    assert injector.pwm_dropped() == set(range(8))


@pytest.mark.parametrize(
    ("fault", "key"),
    [(MotorLoss(start_s=1.0, motor=6), "motor"),
     (MotorDegradation(start_s=1.0, motor=6, efficiency=0.5), "motor"),
     (PwmDropout(start_s=1.0, channel=6), "channel")],
)  # fmt: skip
def test_a_fault_on_a_motor_the_vehicle_lacks_is_one_line_naming_the_key(fault, key):
    faults = (PwmDropout(start_s=0.5, channel=5), fault)
    check_motors(faults, 8, "hexa.toml", "octo")  # an octo has motor 6
    with pytest.raises(ScenarioError) as error:
        check_motors(faults, 6, "hexa.toml", "f550_hexa")
    assert str(error.value) == (
        f"hexa.toml: key 'faults[1].{key}' = 6: vehicle 'f550_hexa' has motors 0..5"
    )
