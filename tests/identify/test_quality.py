"""Quality detectors on arrays with known faults (identify/data/quality.py), fed whole and block by block."""
import numpy as np
import pytest

from identify.data.quality import (MAX_CLIPPED_SHARE, QualityMonitor, RATIO_RANGE, assess_arrays, assess_recording,
                              clip_level, infer_full_scale, verdict)
from identify.data.recording import Recording

FS = 2048.0
SENS = 32767 / 50.0  # the simulated rig: +-50 m/s^2 on int16


def _noisy(n, seed=0, amp=5.0):
    """A live pair of channels: a quantised sine plus noise, as counts / sensitivity."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / FS
    table = amp * np.sin(2 * np.pi * 3 * t) + 0.02 * rng.standard_normal(n)
    mass = 0.7 * amp * np.sin(2 * np.pi * 3 * t + 0.4) + 0.02 * rng.standard_normal(n)
    return np.column_stack([np.round(table * SENS) / SENS, np.round(mass * SENS) / SENS]).astype(np.float32)


def _feed(x, block, full_scale=None):
    mon = QualityMonitor(("table_acc", "mass_acc"), FS, full_scale)
    for a in range(0, x.shape[0], block):
        mon.update(x[a:a + block], a)
    return mon.report()


@pytest.mark.parametrize("block", [64, 1000, 8192, 10**6])
def test_a_channel_dead_from_sample_k_is_flagged_from_k_with_its_count(block):
    x = _noisy(40000)
    k = 12345
    x[k:, 1] = 0.0
    rep = _feed(x, block)
    assert [(f["channel"], f["kind"], f["first"], f["count"]) for f in rep["flags"]] == [("mass_acc", "dead", k, 40000 - k)]
    assert rep["flags"][0]["t_start_s"] == pytest.approx(k / FS)
    usable, reasons = verdict(rep, "table_acc", "mass_acc")
    assert not usable and "mass_acc reads exactly 0 from t = 6.028 s for 27655 samples" in reasons[0]
    # a DAQ file's time axis is the rig's clock: a time on it is also said as how far into the recording
    for f in rep["flags"]:
        f["t_start_s"] += 508.44
    usable, reasons = verdict(rep, "table_acc", "mass_acc")
    assert "mass_acc reads exactly 0 from t = 514.468 s (6.0 s into the recording) for 27655 samples" in reasons[0]


def test_stuck_value_flagged_only_from_the_minimum_length():
    x = _noisy(20000)
    mon = QualityMonitor(("table_acc", "mass_acc"), FS)
    short, long = mon.min_flat - 1, mon.min_flat
    x[5000:5000 + short, 0] = 1.25   # one sample short of the threshold: a live sensor never does this
    x[9000:9000 + long, 0] = 1.25
    rep = _feed(x, 64)
    assert [(f["kind"], f["first"], f["count"], f["value"]) for f in rep["flags"]] == [("stuck", 9000, long, 1.25)]
    assert mon.min_flat == max(64, round(0.05 * FS))


def test_clipped_stretch_is_one_flag_with_its_clipped_samples():
    x = _noisy(30000, amp=10.0)
    level = clip_level(SENS)
    a, b = 8000, 14000
    x[a:b, 1] = np.clip(x[a:b, 1] * 8, -32767 / SENS, 32767 / SENS)  # the mass sensor over its range
    clipped = int(np.count_nonzero(np.abs(x[:, 1]) >= level))
    rep = _feed(x, 64, {c: level for c in ("table_acc", "mass_acc")})
    (f,) = rep["flags"]
    assert (f["channel"], f["kind"], f["samples"]) == ("mass_acc", "clipped", clipped)
    first = a + int(np.argmax(np.abs(x[a:b, 1]) >= level))
    last = a + (b - a - 1) - int(np.argmax(np.abs(x[a:b, 1][::-1]) >= level))
    assert (f["first"], f["first"] + f["count"] - 1) == (first, last)
    assert rep["clipped_share"]["mass_acc"] == pytest.approx(clipped / 30000)
    usable, reasons = verdict(rep, "table_acc", "mass_acc")
    assert not usable and "mass_acc clipped at full scale" in reasons[0]
    # the same share under the limit: flagged, but the recording stays usable
    y = _noisy(30000, amp=10.0)
    n_ok = int(MAX_CLIPPED_SHARE * 30000)
    y[1000:1000 + n_ok, 0] = 32767 / SENS
    rep = _feed(y, 4096, {c: level for c in ("table_acc", "mass_acc")})
    assert rep["flags"][0]["samples"] == n_ok and verdict(rep, "table_acc", "mass_acc") == (True, [])


def test_nan_samples_are_flagged_and_never_count_as_a_stuck_run():
    x = _noisy(20000).astype(float)
    x[7000:7300, 0] = np.nan
    rep = _feed(x, 777)
    assert [(f["channel"], f["kind"], f["first"], f["count"], f["samples"]) for f in rep["flags"]] == [
        ("table_acc", "nonfinite", 7000, 300, 300)]
    assert not verdict(rep, "table_acc", "mass_acc")[0]
    assert rep["rms"]["table_acc"] == pytest.approx(np.nanstd(x[:, 0]), rel=1e-9)


@pytest.mark.parametrize("scale,low", [(1e-3, True), (1e3, False)])
def test_implausible_mass_table_ratio(scale, low):
    x = _noisy(20000).astype(float)
    x[:, 1] *= scale
    rep = _feed(x, 4096)
    ratio = rep["mass_table_rms_ratio"]
    assert ratio == pytest.approx(np.std(x[:, 1]) / np.std(x[:, 0]), rel=1e-9)
    assert (ratio < RATIO_RANGE[0]) if low else (ratio > RATIO_RANGE[1])
    assert [f["kind"] for f in rep["flags"]] == ["ratio"]
    usable, reasons = verdict(rep, "table_acc", "mass_acc")
    assert not usable and "RMS ratio mass_acc/table_acc" in reasons[0]


def test_clean_simulated_sweep_has_no_flags_and_is_usable(table1_run):
    q = assess_recording(table1_run.recording)
    assert q["flags"] == [] and q["usable_for_identification"] and q["reasons"] == []
    assert RATIO_RANGE[0] < q["mass_table_rms_ratio"] < RATIO_RANGE[1]


def test_rails_of_a_file_without_full_scale_are_inferred():
    x = _noisy(30000, amp=10.0).astype(float)
    assert infer_full_scale(x[:, 1]) == (-np.inf, np.inf)  # a noisy signal reaches its extremes once
    x[:, 1] = np.clip(x[:, 1], -6.0, 6.5)  # a sensor clipping at its (unknown) range
    assert infer_full_scale(x[:, 1]) == (-6.0, 6.5)
    rep = assess_arrays({"table_acc": x[:, 0], "mass_acc": x[:, 1]}, FS, pair=("table_acc", "mass_acc"))
    assert rep["clipped_share"]["mass_acc"] == pytest.approx(np.mean((x[:, 1] >= 6.5) | (x[:, 1] <= -6.0)))
    rec = Recording(x[:, 0], x[:, 1], FS, source="clipped.csv")
    assert not assess_recording(rec)["usable_for_identification"]
