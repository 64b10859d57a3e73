"""The lab's file formats (daq/formats): files written by each format's own library read as the same
recording, channels found by name whatever their group or order, units checked, damaged files refused
naming the problem; and CSV time stamps within their printed resolution (issue 31)."""
from __future__ import annotations

import numpy as np
import pytest

from daq.formats import FORMATS, open_recording
from identify.data.channels import STANDARD_GRAVITY_M_S2
from identify.errors import RecordingError
from identify.identifier import SparseIdentifier
from identify.data.recording import write_csv

from .lab_writers import write_csv_exact, write_mdf, write_tdms, write_uff

FS_HZ = 2048.0
#: UFF's E13.5 increment for 1/2048 s, and the rate it reads as
UFF_INCREMENT_S = 4.88281e-04


def _channels(rec) -> dict:
    return {"table_acc": rec.input, "mass_acc": rec.output}


@pytest.fixture(scope="module")
def lab_files(table1_run, tmp_path_factory):
    """The Table 1 sweep written as CSV (17 digits and write_csv's 12), TDMS, UFF 58b and 58, MDF4."""
    d = tmp_path_factory.mktemp("lab")
    ch = _channels(table1_run.recording)
    files = {"csv": d / "r.csv", "csv12": d / "r12.csv", "tdms": d / "r.tdms", "uff": d / "r.uff",
             "uff_ascii": d / "ra.unv", "mdf": d / "r.mf4"}
    write_csv_exact(files["csv"], FS_HZ, ch)
    write_csv(files["csv12"], table1_run.recording)
    write_tdms(files["tdms"], FS_HZ, ch)
    write_uff(files["uff"], FS_HZ, ch, binary=True)
    write_uff(files["uff_ascii"], FS_HZ, ch, binary=False)
    write_mdf(files["mdf"], FS_HZ, ch)
    return files


def _worst_relative(a: dict, b: dict) -> float:
    """Largest relative difference of two models' coefficients (same terms required)."""
    worst = 0.0
    for eq in a:
        assert set(a[eq]) == set(b[eq]), (eq, set(a[eq]) ^ set(b[eq]))
        worst = max([worst] + [abs(b[eq][t] / c - 1) for t, c in a[eq].items()])
    return worst


@pytest.mark.slow
def test_every_format_reads_the_same_samples(lab_files, table1_run):
    """float64 writers (CSV at 17 digits, TDMS, UFF 58b, MDF4) give the samples bit for bit, at 2048 Hz
    exactly (UFF given --fs: its E13.5 increment is not); ASCII UFF's 12 digits equal write_csv's."""
    truth = table1_run.recording
    for name, fs in (("csv", None), ("tdms", None), ("mdf", None), ("uff", FS_HZ)):
        rec = open_recording(lab_files[name], fs_hz=fs)
        assert np.array_equal(rec.input, truth.input) and np.array_equal(rec.output, truth.output), name
        assert rec.fs_hz == FS_HZ and rec.units == ("m/s^2", "m/s^2") and "warnings" not in rec.metadata, name
    ascii_uff, csv12 = open_recording(lab_files["uff_ascii"], fs_hz=FS_HZ), open_recording(lab_files["csv12"])
    assert np.array_equal(ascii_uff.output, csv12.output) and np.array_equal(ascii_uff.input, csv12.input)


@pytest.mark.slow
def test_the_same_recording_in_every_format_gives_the_same_model(lab_files):
    """Coefficient by coefficient within 1e-9 relative (issue 34's acceptance), through SparseIdentifier."""
    def model(path, **kw):
        return SparseIdentifier(bias_replicates=0, placements=0).fit(open_recording(path, **kw)).model_.equations

    reference = model(lab_files["csv"])
    for name, kw in (("tdms", {}), ("mdf", {}), ("uff", {"fs_hz": FS_HZ})):
        worst = _worst_relative(reference, model(lab_files[name], **kw))
        print(f"{name}: worst relative coefficient difference to CSV {worst:.2e}")
        assert worst <= 1e-9, name
    worst = _worst_relative(model(lab_files["csv12"]), model(lab_files["uff_ascii"], fs_hz=FS_HZ))
    print(f"ASCII UFF against write_csv's CSV (both 12 digits): {worst:.2e}")
    assert worst <= 1e-9


def test_uff_stores_the_increment_to_six_digits(lab_files, table1_run):
    """1/2048 s is stored as 4.88281e-04: without --fs the rate is that (2048.00105 Hz) and the recording
    says so, naming --fs 2048; --fs within the stored resolution gives the exact rate; --fs far off is
    refused."""
    rec = open_recording(lab_files["uff"])
    assert rec.fs_hz == pytest.approx(1 / UFF_INCREMENT_S, rel=1e-12) and rec.fs_hz != FS_HZ
    (note,) = rec.metadata["warnings"]
    assert "E13.5" in note and "give --fs 2048" in note
    assert open_recording(lab_files["uff"], fs_hz=FS_HZ).fs_hz == FS_HZ
    with pytest.raises(RecordingError, match=r"sample rate given \(1024 Hz, --fs\) disagrees"):
        open_recording(lab_files["uff"], fs_hz=1024.0)


def test_tdms_channels_are_found_by_name_whatever_the_group(tmp_path, table1_run):
    """Table and mass in groups of their own, written in 3 segments beside another group's channel: read
    by name; a name in two groups is refused naming both, and GROUP/NAME picks one."""
    rec = table1_run.recording
    path = tmp_path / "groups.tdms"
    write_tdms(path, FS_HZ, {"table_acc": rec.input, "mass_acc": rec.output, "temperature": rec.input * 0 + 21.0},
               groups={"table_acc": "Table", "mass_acc": "Mass", "temperature": "Climate"},
               units={"temperature": "degC"}, segments=3)
    back = open_recording(path)
    assert np.array_equal(back.input, rec.input) and np.array_equal(back.output, rec.output)
    twice = tmp_path / "twice.tdms"
    write_tdms(twice, FS_HZ, {"run1/table_acc": rec.input, "run1/mass_acc": rec.output,
                              "run2/table_acc": -rec.input, "run2/mass_acc": -rec.output},
               groups={"run1/table_acc": "run1", "run1/mass_acc": "run1", "run2/table_acc": "run2",
                       "run2/mass_acc": "run2"})
    with pytest.raises(RecordingError, match=r"channel 'table_acc' is in 2 groups \('run1', 'run2'\): name it "
                                             r"with its group, e.g. 'run1/table_acc'"):
        open_recording(twice)
    second = open_recording(twice, input="run2/table_acc", output="run2/mass_acc")
    assert np.array_equal(second.input, -rec.input)


def test_uff_datasets_are_found_by_id1_in_any_order(tmp_path, table1_run):
    rec = table1_run.recording
    path = tmp_path / "shuffled.uff"
    write_uff(path, FS_HZ, {"force": rec.input * 3.0, "mass_acc": rec.output, "table_acc": rec.input},
              units={"force": "N"})
    back = open_recording(path, fs_hz=FS_HZ)
    assert np.array_equal(back.input, rec.input) and np.array_equal(back.output, rec.output)
    with pytest.raises(RecordingError, match=r"missing dataset\(s\) 'table'; found 'force', 'mass_acc', 'table_acc'"):
        open_recording(path, input="table", fs_hz=FS_HZ)


@pytest.mark.parametrize("writer,suffix,unit", [(write_tdms, ".tdms", "V"), (write_uff, ".uff", "N"),
                                                (write_mdf, ".mf4", "m/s")])
def test_an_acceleration_in_another_unit_is_refused(tmp_path, table1_run, writer, suffix, unit):
    rec = table1_run.recording
    path = tmp_path / f"units{suffix}"
    writer(path, FS_HZ, _channels(rec), units={"mass_acc": unit})
    with pytest.raises(RecordingError, match=rf"'mass_acc' is in '{unit}', not an acceleration: the base layout "
                                             r"reads the table's and the mass's accelerations in m/s\^2"):
        open_recording(path, fs_hz=FS_HZ)
    # the force layout takes the file's own units (Silverbox: volts)
    assert open_recording(path, "force", "table_acc", "mass_acc", fs_hz=FS_HZ).units == ("m/s^2", unit)


def test_an_acceleration_in_g_is_converted(tmp_path, table1_run):
    """g is the standard gravity, 9.80665 m/s^2 exactly: the samples come back in m/s^2, to rounding."""
    rec = table1_run.recording
    path = tmp_path / "in_g.tdms"
    write_tdms(path, FS_HZ, {k: v / STANDARD_GRAVITY_M_S2 for k, v in _channels(rec).items()},
               units={"table_acc": "g", "mass_acc": "g"})
    back = open_recording(path)
    np.testing.assert_allclose(back.output, rec.output, rtol=4e-16, atol=0)
    assert back.units == ("m/s^2", "m/s^2")
    assert back.metadata["warnings"] == ["channel 'table_acc' converted from g to m/s^2 (x 9.80665)",
                                         "channel 'mass_acc' converted from g to m/s^2 (x 9.80665)"]


def _cut(src, dst, fraction: float):
    data = src.read_bytes()
    dst.write_bytes(data[:int(len(data) * fraction)])
    return dst


def _damaged(case: str, files: dict, d):
    """(the damaged file, what the refusal must say) for each way a lab file arrives broken."""
    if case == "tdms_garbage":
        (d / "g.tdms").write_bytes(b"not a tdms file at all\n" * 20)
        return d / "g.tdms", r"not in TDMS format \(TDMS files begin with 'TDSm'\)"
    if case == "tdms_cut":
        return _cut(files["tdms"], d / "c.tdms", 0.6), "cut short: its last TDMS segment announces"
    if case == "mdf_named_tdms":
        (d / "m.tdms").write_bytes(files["mdf"].read_bytes())
        return d / "m.tdms", "it looks like a MDF4 file, whose names end in .mf4"
    if case == "mdf_garbage":
        (d / "g.mf4").write_bytes(b"\x00\x01" * 100)
        return d / "g.mf4", r"not in MDF4 format \(MDF files begin with 'MDF'\)"
    if case == "mdf_cut":
        return _cut(files["mdf"], d / "c.mf4", 0.6), "not a readable MDF4 file"
    if case == "mdf_unfinished":
        (d / "u.mf4").write_bytes(b"UnFinMF " + files["mdf"].read_bytes()[8:])
        return d / "u.mf4", r"its writer did not finalise this MDF file \(UnFinMF\)"
    if case in ("uff_cut", "uff_ascii_cut"):
        src = files["uff" if case == "uff_cut" else "uff_ascii"]
        return _cut(src, d / f"c{src.suffix}", 0.7), "cut short: the last UFF dataset is not closed"
    if case == "uff_garbage":
        (d / "g.uff").write_text("hello\nworld\n")
        return d / "g.uff", r"not in UFF58 format \(UFF files begin with a '-1' line"
    if case == "csv_cut":  # cut in the middle of the last line's last value
        text = files["csv12"].read_text()
        (d / "c.csv").write_text(text[:text.rstrip("\n").rfind(",") + 4])
        return d / "c.csv", "does not end with a line break: the file looks cut short"
    if case == "h5_garbage":
        (d / "g.h5").write_text("t,table_acc\n")
        return d / "g.h5", "not an HDF5 file"
    (d / "g.mat").write_bytes(b"\x00\x01garbage" * 50)
    return d / "g.mat", "not a readable MAT file"


DAMAGED = ["tdms_garbage", "tdms_cut", "mdf_named_tdms", "mdf_garbage", "mdf_cut", "mdf_unfinished", "uff_cut",
           "uff_ascii_cut", "uff_garbage", "csv_cut", "h5_garbage", "mat_garbage"]


@pytest.mark.parametrize("case", DAMAGED)
def test_a_damaged_file_is_refused_naming_the_problem(lab_files, tmp_path, case):
    path, message = _damaged(case, lab_files, tmp_path)
    with pytest.raises(RecordingError, match=message) as refused:
        open_recording(path, fs_hz=FS_HZ)
    assert str(refused.value).startswith(f"{path}: ")


def test_every_format_has_a_damaged_case():
    """A format added to the registry without a damaged-file case here fails this test."""
    format_of_case = {"tdms": "TDMS", "mdf": "MDF4", "uff": "UFF58", "csv": "CSV", "h5": "HDF5", "mat": "MAT"}
    assert {f.name for f in FORMATS} == {format_of_case[case.split("_")[0]] for case in DAMAGED}


def _csv_printed(path, t, a, b, time_format: str):
    rows = "".join(f"{time_format % x},{float(y)!r},{float(z)!r}\n" for x, y, z in zip(t, a, b))
    path.write_text("t,table_acc,mass_acc\n" + rows)
    return path


@pytest.mark.slow
def test_csv_time_stamps_are_read_within_their_printed_resolution(tmp_path, table1_run):
    """Issue 31: stamps printed to the microsecond (%.6f) at 2048 Hz step 488 or 489 us: accepted, the rate
    from the span (2048 Hz to 1e-8); a dropped sample is still refused; stamps printed to the millisecond
    cannot tell 0.49 ms steps apart and are refused."""
    rec = table1_run.recording
    t = np.arange(rec.n_samples) / FS_HZ
    back = open_recording(_csv_printed(tmp_path / "us.csv", t, rec.input, rec.output, "%.6f"))
    assert back.fs_hz == pytest.approx(FS_HZ, rel=1e-8) and np.array_equal(back.output, rec.output)
    keep = np.ones(rec.n_samples, bool)
    keep[5000] = False
    with pytest.raises(RecordingError, match="not uniformly sampled: step 0.000977 s at sample 5000.*printed to 1e-06 s"):
        open_recording(_csv_printed(tmp_path / "gap.csv", t[keep], rec.input[keep], rec.output[keep], "%.6f"))
    with pytest.raises(RecordingError, match="time column 't' is not strictly increasing"):
        open_recording(_csv_printed(tmp_path / "ms.csv", t, rec.input, rec.output, "%.3f"))
