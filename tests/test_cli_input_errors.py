"""Command-line inputs that are wrong get one line naming the file, the line and column, or the
value that is the problem (not only the expected form)."""

import pytest

from idm_rs.apps.cli import main


def _error(capsys, argv) -> str:
    assert main(argv) == 2
    return capsys.readouterr().err.strip()


def test_a_log_spaced_range_from_zero_names_the_zero(capsys):
    err = _error(capsys, ["characterize", "--frequencies", "0:100:5"])
    assert "log-spaced, so A and B must be > 0 (got A = 0)" in err and "cannot read" not in err
    assert "every value must be > 0, got 0" in _error(capsys, ["characterize", "--frequencies", "10,0"])
    assert "N must be a positive integer, got 'x'" in _error(capsys, ["characterize", "--voltages", "40:120:x"])


@pytest.mark.parametrize("text, expected", [
    ("t,v\n0,0\n1e-3,80\n2e-3,abc\n", "v.csv, line 4, column 2: cannot read 'abc' as a number"),
    ("# a comment\nt,v\n0,0\nnan?,1\n", "v.csv, line 4, column 1: cannot read 'nan?' as a number"),
    ("0,0\n1e-3,80\n0.5e-3,0\n", "v.csv: times must increase strictly; sample 3 (t = 0.0005 s) is not after sample 2"),
    ("t,v\n0\n", "v.csv, line 2: needs two columns"),
    ("t,v\n0,0\n", "v.csv: 1 sample(s); a sampled input needs at least 2"),
])
def test_a_voltage_csv_error_names_the_file_line_and_column(tmp_path, capsys, text, expected):
    path = tmp_path / "v.csv"
    path.write_text(text)
    err = _error(capsys, ["simulate", "--voltage-csv", str(path)])
    assert str(tmp_path) in err and expected in err, err


def test_a_missing_voltage_csv_is_named(tmp_path, capsys):
    assert f"--voltage-csv {tmp_path / 'no.csv'}: no such file" in _error(
        capsys, ["simulate", "--voltage-csv", str(tmp_path / "no.csv")])
