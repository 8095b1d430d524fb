"""The RTL-equals-TLM scoreboard: silent on agreement, and the first mismatch named exactly."""

import asyncio

import pytest

from fpga_hdl.buses.transactions import I2cNack, TlmI2cBus, TlmSpiBus
from fpga_hdl.chips.ist8310.model import Ist8310Model
from fpga_hdl.chips.mpu6000.model import Mpu6000Model
from fpga_hdl.verification.scoreboard import (
    Scoreboard,
    ScoreboardMismatch,
    ScoredI2cBus,
    ScoredSpiBus,
)


def test_agreeing_transactions_are_recorded():
    scoreboard = Scoreboard()
    scoreboard.check("spi imu 75", b"\x00\x68", b"\x00\x68")
    scoreboard.check("frame 1", (1.0, 2.0), (1.0, 2.0))
    assert len(scoreboard) == 2
    assert scoreboard.transactions[0].request == "spi imu 75"


def test_the_first_mismatch_names_index_request_both_results_and_the_byte():
    scoreboard = Scoreboard()
    scoreboard.check("spi imu 75", b"\x00\x68", b"\x00\x68")
    message = (
        r"^RTL vs TLM: transaction 1 \(i2c 0x0E write 03 read 3\): expected 0a0b0c, "
        r"got 0a0b0d; first difference at byte 2$"
    )
    with pytest.raises(ScoreboardMismatch, match=message):
        scoreboard.check("i2c 0x0E write 03 read 3", b"\x0a\x0b\x0c", b"\x0a\x0b\x0d")


def test_transcripts_diverging_or_of_different_length_fail():
    rows = [["spi:imu", "f500", "0068"], ["i2c:0e", "00+1", "nack0"]]
    Scoreboard().check_transcript(rows, [list(row) for row in rows])
    with pytest.raises(
        ScoreboardMismatch, match=r"transaction 1 \(i2c:0e 00\+1\): expected nack0, got 10$"
    ):
        Scoreboard().check_transcript(rows, [rows[0], ["i2c:0e", "00+1", "10"]])
    with pytest.raises(ScoreboardMismatch, match=r"expected i2c:0e 00\+1 nack0, got i2c:0c 00\+1"):
        Scoreboard().check_transcript(rows, [rows[0], ["i2c:0c", "00+1", "nack0"]])
    with pytest.raises(ScoreboardMismatch, match=r"^fast path: expected 2 transactions, got 1$"):
        Scoreboard("fast path").check_transcript(rows, rows[:1])


def test_scored_spi_bus_returns_the_rtl_answer_and_fails_on_a_flipped_byte():
    rtl_model, tlm_model = Mpu6000Model(), Mpu6000Model()
    bus = ScoredSpiBus(TlmSpiBus({"imu": rtl_model}), TlmSpiBus({"imu": tlm_model}))
    assert asyncio.run(bus.transfer("imu", b"\xf5\x00", sclk_hz=1e6)) == b"\x00\x68"
    rtl_model.fault_flip = 0x01  # the stand-in "RTL" now answers differently
    with pytest.raises(ScoreboardMismatch, match=r"transaction 1 \(spi imu f500 at 1e\+06 Hz\)"):
        asyncio.run(bus.transfer("imu", b"\xf5\x00", sclk_hz=1e6))


def test_scored_i2c_bus_scores_nacks_as_outcomes():
    rtl_model, tlm_model = Ist8310Model(), Ist8310Model()
    scoreboard = Scoreboard()
    bus = ScoredI2cBus(TlmI2cBus({0x0E: rtl_model}), TlmI2cBus({0x0E: tlm_model}), scoreboard)
    assert asyncio.run(bus.write_read(0x0E, b"\x00", 1, scl_hz=400e3)) == b"\x10"
    with pytest.raises(I2cNack, match=r"^I2C target 0x0C did not acknowledge the address$"):
        asyncio.run(bus.write_read(0x0C, b"\x00", 1, scl_hz=400e3))  # both NACK: agreed
    rtl_model.fault_mute = True
    with pytest.raises(ScoreboardMismatch, match=r"expected 10, got NACK of byte 0$"):
        asyncio.run(bus.write_read(0x0E, b"\x00", 1, scl_hz=400e3))
    assert len(scoreboard) == 3
