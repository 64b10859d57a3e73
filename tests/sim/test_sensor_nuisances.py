"""The accelerometer's measurement nuisances (sim/sensors.py): mains hum and an N-bit converter, exactly as
stated against the fault-free readings of the same noise draw."""
import numpy as np
import pytest

from sim.sensors import Accelerometer

FS = 1000.0


def _signal():
    t = np.arange(20000) / FS
    return 3.0 * np.sin(2 * np.pi * 7.3 * t) * np.exp(-t / 10)


def test_hum_is_the_stated_sine_on_top_of_the_healthy_readings():
    x = _signal()
    healthy = Accelerometer(noise_fraction=0.01).measure(x, np.random.default_rng(4), FS)
    humming = Accelerometer(noise_fraction=0.01, hum_fraction=0.03, hum_hz=60.0, hum_phase_rad=0.7)
    y = humming.measure(x, np.random.default_rng(4), FS)
    t = np.arange(x.size) / FS
    hum = y - healthy
    np.testing.assert_allclose(hum, 0.03 * np.std(x) * np.sqrt(2) * np.sin(2 * np.pi * 60.0 * t + 0.7), atol=1e-12)
    assert np.std(hum) == pytest.approx(0.03 * np.std(x), rel=1e-3)  # RMS = the stated fraction of the std
    assert humming.faults() == {"hum_fraction": 0.03, "hum_hz": 60.0, "hum_phase_rad": 0.7}


@pytest.mark.parametrize("bits", [10, 16])
def test_quantisation_rounds_to_the_converter_step_over_the_record(bits):
    x = _signal()
    healthy = Accelerometer(noise_fraction=0.01).measure(x, np.random.default_rng(2), FS)
    sensor = Accelerometer(noise_fraction=0.01, adc_bits=bits)
    y = sensor.measure(x, np.random.default_rng(2), FS)
    step = 2 * np.max(np.abs(healthy)) / 2**bits
    assert np.max(np.abs(y - healthy)) <= step / 2 + 1e-12
    np.testing.assert_allclose(y / step, np.round(y / step), atol=1e-9)  # on the grid
    assert np.unique(y).size <= 2**bits + 1
    assert sensor.faults() == {"adc_bits": bits} and Accelerometer().faults() == {}


def test_nuisance_settings_out_of_range_are_refused():
    with pytest.raises(ValueError, match="adc_bits"):
        Accelerometer(adc_bits=1)
    with pytest.raises(ValueError, match="hum"):
        Accelerometer(hum_fraction=-0.1)
    with pytest.raises(ValueError, match="fs_hz"):
        Accelerometer(hum_fraction=0.01).measure(_signal(), np.random.default_rng(0))
