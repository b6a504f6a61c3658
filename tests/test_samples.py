import numpy as np
import pytest

from conftest import SEED_DM, SEED_QE
from planecal.errors import InputError
from planecal.samples import SampleWriter, read_samples, write_samples
from planecal.paths import data_path


def test_reads_the_seed_format(tmp_path):
    s = read_samples(data_path("examples", "seed_samples.tsv"))  # comma decimals, header, CRLF
    np.testing.assert_array_equal(s.qe, SEED_QE)
    np.testing.assert_array_equal(s.d_mm, SEED_DM)
    assert s.n_zero == 0 and list(s.lines) == [2, 3, 4, 5, 6]


def test_round_trip_and_dot_decimals_without_header(tmp_path):
    p = tmp_path / "a.tsv"
    write_samples(p, SEED_QE, SEED_DM + 0.0000004)
    s = read_samples(p)
    np.testing.assert_array_equal(s.qe, SEED_QE)
    np.testing.assert_allclose(s.d_mm, SEED_DM + 0.0000004, atol=1e-12)
    body = "".join(p.read_text().splitlines(keepends=True)[1:])
    (tmp_path / "b.tsv").write_text(body)
    assert len(read_samples(tmp_path / "b.tsv")) == 5


def test_laser_zeros_are_skipped_and_counted(tmp_path):
    p = tmp_path / "z.tsv"
    p.write_text("8416544\t8371251\t8443192\t8360940\t8321861\t8334082\t0\n"
                 "8416544\t8371251\t8443192\t8360940\t8321861\t8334082\t0,00\n"
                 "8413857\t8368248\t8434524\t8358003\t8326447\t8334590\t85,30\n")
    s = read_samples(p)
    assert len(s) == 1 and s.n_zero == 2 and s.lines[0] == 3


@pytest.mark.parametrize("content, message", [
    ("", r"x.tsv: no samples in the file"),
    ("q1\tq2\tq3\tq4\tq5\tq6\tDm\n", r"x.tsv: no samples"),
    ("1\t2\t3\t4\t5\t6\t0\n", r"no samples in the file \(1 laser zeros\)"),
    ("q1\tq2\tq3\tq4\tq5\tq6\tDm\n1\t2\t3\t4\t5\t80,0\n", r"x.tsv:2: expected 7 tab-separated columns .* found 6"),
    ("1\t2\t3\t4\t5\t6\t7\t8\t9\n", r"x.tsv:1: expected 7 .* found 9"),
    ("1\t2\tx3\t4\t5\t6\t80\n", r"x.tsv:1: column q3 is not an integer encoder count: 'x3'"),
    ("1\t2\t3.5\t4\t5\t6\t80\n", r"x.tsv:1: column q3 is not an integer"),
    ("1\t2\t3\t4\t5\t6\tabc\n", r"x.tsv:1: column Dm is not a number: 'abc'"),
    ("1\t2\t3\t4\t5\t6\tNaN\n", r"x.tsv:1: column Dm = 'NaN' is not a finite"),
    ("1\t2\t3\t4\t5\t6\tinf\n", r"x.tsv:1: column Dm = 'inf' is not a finite"),
    ("1\t2\t3\t4\t5\t6\t-3\n", r"x.tsv:1: column Dm = '-3' is not a finite, non-negative"),
    ("1\t2\t3\t4\t5\t16777216\t80\n", r"x.tsv:1: column q6 = 16777216 is outside the 24-bit"),
    ("1\t-2\t3\t4\t5\t6\t80\n", r"x.tsv:1: column q2 = -2 is outside the 24-bit"),
    ("1\t2\t3\t4\t5\t6\t80\t0\n", r"x.tsv:1: column plate must be a 1-based plate number"),
    ("1\t2\t3\t4\t5\t6\t80\nq1\tq2\tq3\tq4\tq5\tq6\tDm\n", r"x.tsv:2: header line in the middle"),
])
def test_malformed_files_name_file_line_and_problem(tmp_path, content, message):
    p = tmp_path / "x.tsv"
    p.write_text(content)
    with pytest.raises(InputError, match=message):
        read_samples(p)


def test_missing_file(tmp_path):
    with pytest.raises(InputError, match="nope.tsv: file not found"):
        read_samples(tmp_path / "nope.tsv")


def test_writer_flushes_each_sample_and_repairs_a_torn_tail(tmp_path):
    p = tmp_path / "run.tsv"
    w = SampleWriter(p)
    w.write(SEED_QE[0], 92.52)
    assert len(read_samples(p)) == 1  # on disk before close
    w.write(SEED_QE[1], 85.3)
    w.close()
    with open(p, "a") as f:  # a run killed in the middle of a line
        f.write("8406018\t8362")
    with SampleWriter(p, append=True) as w:
        w.write(SEED_QE[2], 69.86)
    s = read_samples(p)
    np.testing.assert_array_equal(s.qe, SEED_QE[:3])


def test_plate_column(tmp_path):
    p = tmp_path / "m.tsv"
    write_samples(p, SEED_QE, SEED_DM, plate=np.array([0, 1, 2, 1, 0]))
    s = read_samples(p)
    assert list(s.plate) == [0, 1, 2, 1, 0]
