"""Readers: every bad file ends in a RecordingError that names the file and the problem."""
import numpy as np
import pytest
from scipy.io import savemat

from identify.errors import RecordingError
from identify.data.recording import read_recording, write_csv


def _csv(tmp_path, text, name="rec.csv"):
    p = tmp_path / name
    p.write_text(text)
    return p


def _good_rows(n=400, fs=100.0):
    t = np.arange(n) / fs
    return t, np.sin(2 * np.pi * 3 * t), np.cos(2 * np.pi * 3 * t)


def test_csv_roundtrip(tmp_path, table1_run):
    path = tmp_path / "r.csv"
    write_csv(path, table1_run.recording)
    rec = read_recording(path)
    assert rec.fs_hz == pytest.approx(2048.0, rel=1e-9)
    np.testing.assert_allclose(rec.output, table1_run.recording.output, rtol=1e-9, atol=1e-12)


def test_mat_with_variable_mapping_and_sample_rate(tmp_path):
    _, u, y = _good_rows()
    path = tmp_path / "sb.mat"
    savemat(path, {"V1": u[None, :], "V2": y[None, :]})
    rec = read_recording(path, "force", "V1", "V2", fs_hz=610.35)
    assert rec.layout == "force" and rec.fs_hz == 610.35 and rec.n_samples == 400


def test_a_sample_rate_given_must_agree_with_the_time_column(tmp_path, table1_run):
    """--fs is for a file without a time column: one that disagrees with the file's own time column would
    scale every coefficient (1000 Hz for a 2048 Hz sweep gave a stiffness of 113 N/m against 476) and is
    refused; one that agrees is accepted."""
    path = tmp_path / "r.csv"
    write_csv(path, table1_run.recording)
    with pytest.raises(RecordingError, match=r"sample rate given \(1000 Hz, --fs\) disagrees with the time column"):
        read_recording(path, fs_hz=1000.0)
    assert read_recording(path, fs_hz=2048.0).fs_hz == pytest.approx(2048.0, rel=1e-9)


@pytest.mark.parametrize("case,match", [
    ("missing_column", "missing column.*'mass_acc'"),
    ("nan", "column 'mass_acc' has 1 NaN"),
    ("nonuniform", "not uniformly sampled"),
    ("decreasing", "not strictly increasing"),
    ("short", "too short"),
    ("no_header", "header"),
    ("ragged", "line 5 has 2 fields"),
    ("text_value", "non-numeric value"),
    ("empty", "empty file"),
    ("constant_input", "constant"),
])
def test_bad_csv_files(tmp_path, case, match):
    t, a, b = _good_rows()
    rows = [f"{x},{y},{z}" for x, y, z in zip(t, a, b)]
    header = "t,table_acc,mass_acc"
    if case == "missing_column":
        header = "t,table_acc,other"
    elif case == "nan":
        rows[10] = f"{t[10]},{a[10]},nan"
    elif case == "nonuniform":
        rows = rows[:100] + rows[101:]  # a dropped sample
    elif case == "decreasing":
        rows[20], rows[21] = rows[21], rows[20]
    elif case == "short":
        rows = rows[:50]
    elif case == "no_header":
        header = rows.pop(0)
    elif case == "ragged":
        rows[3] = "0.1,0.2"
    elif case == "text_value":
        rows[7] = f"{t[7]},abc,{b[7]}"
    elif case == "empty":
        header, rows = "", []
    elif case == "constant_input":
        rows = [f"{x},1.0,{z}" for x, z in zip(t, b)]
    path = _csv(tmp_path, "\n".join([header] + rows) + "\n")
    with pytest.raises(RecordingError, match=match) as exc:
        read_recording(path)
    assert str(path) in str(exc.value)


def test_unreadable_files(tmp_path):
    with pytest.raises(RecordingError, match="no such file"):
        read_recording(tmp_path / "nope.csv")
    bad_mat = tmp_path / "x.mat"
    bad_mat.write_bytes(b"\x00\x01garbage" * 50)
    with pytest.raises(RecordingError, match="not a readable MAT file"):
        read_recording(bad_mat, fs_hz=100)
    binary = tmp_path / "x.csv"
    binary.write_bytes(bytes(range(256)) * 4)
    with pytest.raises(RecordingError):
        read_recording(binary)
    with pytest.raises(RecordingError, match="unsupported file type"):
        read_recording(_csv(tmp_path, "x", "r.xlsx"))
    with pytest.raises(RecordingError, match="give the sample rate"):
        read_recording(_csv(tmp_path, "a,table_acc,mass_acc\n" + "1,2,3\n" * 300))


@pytest.mark.slow
def test_a_text_column_beside_the_signals_is_left_out(tmp_path, table1_run):
    """A lab's CSV often carries words beside the signals (who ran it, a note): the signals are read as if
    it were not there; asking a signal of it names the column and its first value; a row with a field
    too many is still named."""
    rec = table1_run.recording
    plain, worded = tmp_path / "plain.csv", tmp_path / "worded.csv"
    write_csv(plain, rec)
    lines = plain.read_text().splitlines()
    worded.write_text("\n".join([lines[0] + ",operator"] + [ln + ",alice" for ln in lines[1:]]) + "\n")
    back = read_recording(worded)
    assert np.array_equal(back.input, read_recording(plain).input)
    assert np.array_equal(back.output, read_recording(plain).output) and back.fs_hz == rec.fs_hz
    with pytest.raises(RecordingError, match=r"worded.csv: column 'operator' holds text, not numbers "
                                             r"\(line 2: 'alice'\)"):
        read_recording(worded, output="operator")
    bad = lines[0] + ",operator\n" + "".join(ln + ",alice\n" for ln in lines[1:100]) + lines[100] + ",alice,x\n"
    worded.write_text(bad)
    with pytest.raises(RecordingError, match="line 101 has 5 fields, header has 4"):
        read_recording(worded)
