import numpy as np
import pytest

from conftest import SEED_DM, SEED_QE
from planecal.base.errors import InputError
from planecal.io.samples import HEADER, SampleWriter, read_samples, write_samples
from repo import repo_path


def test_reads_the_seed_format(tmp_path):
    s = read_samples(repo_path("examples", "seed_samples.tsv"))  # comma decimals, header, CRLF
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


# ----- bounded reading and files without information (issue 16) -----------------------------

ROW = "8416544\t8371251\t8443192\t8360940\t8321861\t8334082\t{dm}{plate}\n"


def _rows(dms, plates=None):
    return "".join(ROW.format(dm=dm, plate="" if plates is None or plates[i] is None
                              else f"\t{plates[i]}") for i, dm in enumerate(dms))


def test_plate_column_on_some_lines_only_is_refused(tmp_path):
    p = tmp_path / "m.tsv"
    p.write_text("q1\tq2\tq3\tq4\tq5\tq6\tDm\tplate\n" + _rows([80, 81, 82, 83], [1, 2, None, 3]))
    with pytest.raises(InputError, match=r"^.*m.tsv:4: 7 columns, but line 2 has 8: the plate "
                                         r"column must be on every line or on none$"):
        read_samples(p)


def test_one_row_repeated_has_no_information(tmp_path):
    p = tmp_path / "same.tsv"
    p.write_text("q1\tq2\tq3\tq4\tq5\tq6\tDm\n" + _rows(["85,30"] * 40))
    with pytest.raises(InputError, match=r"same.tsv: all 40 samples are line 2 repeated: no "
                                         r"information to calibrate from$"):
        read_samples(p)
    p.write_text(_rows(["85,30"] * 39 + ["85,31"]))  # one pose, noise in the reading: data
    assert len(read_samples(p)) == 40


def test_readings_outside_the_scene_laser_window(tmp_path):
    from planecal.io.samples import check_samples
    from planecal.model.scene import load_scene
    scene = load_scene("thesis_final")  # ZS-LD80 window 65-95 mm
    p = tmp_path / "w.tsv"
    p.write_text(_rows([80, 95, 500, 65]))
    s = read_samples(p)  # plausible for some laser: read
    with pytest.raises(InputError, match=r"w.tsv:3: Dm = 500 mm is outside the laser window "
                                         r"65-95 mm of scene thesis_final: not a reading this "
                                         r"sensor gives \(1 such samples\)$"):
        check_samples(s, scene)
    with pytest.raises(InputError, match=r"w.tsv:3: Dm = 500 mm is outside"):
        read_samples(p, scene)
    p.write_text(_rows([80, 95, 65]))
    assert len(read_samples(p, scene)) == 3  # the window's ends are readings


def test_plate_numbers_the_scene_lacks(tmp_path):
    from planecal.io.samples import read_many
    from planecal.model.scene import load_scene
    p = tmp_path / "k.tsv"
    p.write_text(_rows([80, 81, 82], [1, 3, 5]))
    with pytest.raises(InputError, match=r"k.tsv:3: plate 5, but scene three_plates has 4 plates$"):
        read_many([repo_path("examples", "seed_samples.tsv"), p], load_scene("three_plates"))
    with pytest.raises(InputError, match=r"k.tsv:2: plate 3, but scene thesis_final has 1 plate$"):
        read_samples(p, load_scene("thesis_final"))


@pytest.mark.parametrize("content, message", [
    ("1\t2\t3\t4\t5\t6\t1e308\n",
     r"x.tsv:1: column Dm = 1e308 mm is not a plausible laser distance \(at most 10000 mm\)$"),
    ("1\t2\t3\t\u0663\t5\t6\t80\n", r"x.tsv:1: column q4 is not an integer encoder count: '\u0663'$"),
    ("1\t2\t3\t4\t5\t6\t8\u0660\n", r"x.tsv:1: column Dm is not a number: '8\u0660'$"),
    ("1\t2\t3\t4_0\t5\t6\t80\n", r"x.tsv:1: column q4 is not an integer encoder count: '4_0'$"),
    ("1\t2\t3\t4\t5\t6\t80\t1x\n", r"x.tsv:1: column plate must be a 1-based plate number, got '1x'$"),
    ("1\t2\t3\t4\t5\t6\t80\n\x00\x00", r"x.tsv:2: binary data \(NUL bytes\), not a text sample "
                                       r"file \(UTF-16\? save it as UTF-8\)$"),
    ("1\t2\t3\t4\t5\t6\t80" + " " * 2000 + "\n",
     r"x.tsv:1: line longer than 1024 characters, not a sample file \(a sample line is ~60\)$"),
])
def test_implausible_lines(tmp_path, content, message):
    p = tmp_path / "x.tsv"
    p.write_text(content, encoding="utf-8")
    with pytest.raises(InputError, match=message):
        read_samples(p)


def test_utf16_file_is_named_binary(tmp_path):
    p = tmp_path / "u16.tsv"
    p.write_text("q1\tq2\tq3\tq4\tq5\tq6\tDm\n", encoding="utf-16")
    with pytest.raises(InputError, match=r"u16.tsv:1: binary data \(NUL bytes\)"):
        read_samples(p)


def test_caps_on_lines_and_size(tmp_path, monkeypatch):
    import planecal.io.samples as samples
    p = tmp_path / "long.tsv"
    p.write_text(_rows([80 + i * 0.01 for i in range(12)]))
    monkeypatch.setattr(samples, "MAX_LINES", 10)
    with pytest.raises(InputError, match=r"long.tsv: more than 10 lines, too many for a sample "
                                         r"file \(a run has hundreds\)$"):
        read_samples(p)
    monkeypatch.setattr(samples, "MAX_LINES", 12)
    assert len(read_samples(p)) == 12
    monkeypatch.setattr(samples, "MAX_FILE_BYTES", 2**20)
    big = tmp_path / "big.tsv"
    big.write_bytes(b"#" * (3 * 2**20))
    with pytest.raises(InputError, match=r"big.tsv: 3 MiB is too large for a sample file \(at "
                                         r"most 1 MiB; a 150-sample run is ~10 kB\)$"):
        read_samples(big)


def test_special_paths(tmp_path):
    with pytest.raises(InputError, match=r"^/dev/zero:1: binary data \(NUL bytes\)"):
        read_samples("/dev/zero")
    with pytest.raises(InputError, match=r"is a directory, not a sample file$"):
        read_samples(tmp_path)


def test_calibrate_dev_zero_exits_2_with_one_line(capsys):
    from planecal.cli import main
    assert main(["calibrate", "/dev/zero"]) == 2
    err = capsys.readouterr().err
    assert err == ("planecal calibrate: error: /dev/zero:1: binary data (NUL bytes), not a text "
                   "sample file (UTF-16? save it as UTF-8)\n")


def test_large_file_is_stored_compactly(tmp_path):
    """20,000 samples: the arrays are the int64/float64 the callers get, line numbers kept."""
    rng = np.random.default_rng(0)
    qe = rng.integers(8_000_000, 9_000_000, (20_000, 6))
    dm = rng.uniform(65, 95, 20_000)
    p = tmp_path / "n.tsv"
    from planecal.io.samples import format_line  # write_samples fsyncs each line: slow here
    p.write_text("\t".join(HEADER) + "\n" + "".join(format_line(q, d) for q, d in zip(qe, dm)))
    s = read_samples(p)
    np.testing.assert_array_equal(s.qe, qe)
    np.testing.assert_allclose(s.d_mm, dm, atol=5e-7)
    assert s.qe.dtype == np.int64 and s.lines[0] == 2 and s.lines[-1] == 20_001


# ----- the approach direction group dir1..dir6 (issue 22) ------------------------------------

DIRS = np.array([[1, -1, 0, 1, 1, -1], [-1, -1, 1, 0, 1, 1], [0, 0, 0, 0, 0, 0],
                 [1, 1, 1, 1, 1, 1], [-1, -1, -1, -1, -1, -1]], np.int8)
HEAD = "q1\tq2\tq3\tq4\tq5\tq6\tDm"
GROUP = "\tdir1\tdir2\tdir3\tdir4\tdir5\tdir6"


@pytest.mark.parametrize("plate", [None, np.array([0, 1, 2, 1, 0])])
def test_direction_group_round_trip(tmp_path, plate):
    p = tmp_path / "d.tsv"
    write_samples(p, SEED_QE, SEED_DM, plate, direction=DIRS)
    head, first = p.read_text().splitlines()[:2]
    assert head == HEAD + ("\tplate" if plate is not None else "") + GROUP
    assert first.split("\t")[-6:] == ["1", "-1", "0", "1", "1", "-1"]
    s = read_samples(p)
    assert s.direction.dtype == np.int8
    np.testing.assert_array_equal(s.direction, DIRS)
    np.testing.assert_array_equal(s.qe, SEED_QE)
    np.testing.assert_array_equal(s.d_mm, SEED_DM)
    if plate is not None:
        np.testing.assert_array_equal(s.plate, plate)
    sub = s.subset(np.array([3, 1]))
    np.testing.assert_array_equal(sub.direction, DIRS[[3, 1]])


def test_files_without_the_group_read_as_before(tmp_path):
    for path in (repo_path("examples", "seed_samples.tsv"),
                 repo_path("tests", "corpus", "base", "run.tsv"),
                 repo_path("tests", "corpus", "base", "run3.tsv")):
        s = read_samples(path)
        assert s.direction is None and s.subset(np.arange(2)).direction is None
    p = tmp_path / "old.tsv"
    write_samples(p, SEED_QE, SEED_DM, np.array([0, 1, 2, 1, 0]))  # no direction: no group
    assert p.read_text().splitlines()[0] == HEAD + "\tplate"
    assert read_samples(p).direction is None


def test_read_many_carries_the_group_unknown_where_a_file_lacks_it(tmp_path):
    from planecal.io.samples import read_many
    write_samples(tmp_path / "a.tsv", SEED_QE, SEED_DM, direction=DIRS)
    write_samples(tmp_path / "b.tsv", SEED_QE[:2] + 7, SEED_DM[:2])
    s = read_many([tmp_path / "a.tsv", tmp_path / "b.tsv"])
    np.testing.assert_array_equal(s.direction, np.vstack([DIRS, np.zeros((2, 6))]))
    assert read_many([tmp_path / "b.tsv"]).direction is None


def test_a_continued_file_keeps_its_columns(tmp_path):
    """append (--resume) keeps the columns the file has, whatever the new writer asks."""
    with_group, without = tmp_path / "g.tsv", tmp_path / "n.tsv"
    with SampleWriter(with_group, with_direction=True) as w:
        w.write(SEED_QE[0], SEED_DM[0], None, DIRS[0])
    with SampleWriter(with_group, append=True) as w:  # not asked: the file has it
        w.write(SEED_QE[1], SEED_DM[1], None, DIRS[1])
        with pytest.raises(ValueError, match="direction group"):
            w.write(SEED_QE[2], SEED_DM[2])  # a sample without its direction
    np.testing.assert_array_equal(read_samples(with_group).direction, DIRS[:2])
    with SampleWriter(without) as w:
        w.write(SEED_QE[0], SEED_DM[0])
    with SampleWriter(without, append=True, with_direction=True) as w:  # begun without
        w.write(SEED_QE[1], SEED_DM[1], None, DIRS[1])
    s = read_samples(without)
    assert len(s) == 2 and s.direction is None


LINE = "8416544\t8371251\t8443192\t8360940\t8321861\t8334082\t80,5"
D6 = "\t1\t-1\t0\t1\t1\t-1"


@pytest.mark.parametrize("content, message", [
    (HEAD + GROUP + "\n" + LINE + "\t1\t-1\t2\t1\t1\t-1\n",
     r"x.tsv:2: column dir3 must be -1, 0 or 1 .*got '2'"),
    (HEAD + GROUP + "\n" + LINE + "\t1\t-1\t+\t1\t1\t-1\n", r"x.tsv:2: column dir3 must be"),
    (HEAD + GROUP + "\n" + LINE + "\t1\t-1\t0.0\t1\t1\t-1\n", r"x.tsv:2: column dir3 must be"),
    (HEAD + GROUP + "\n" + LINE + D6 + "\n" + LINE + "\n",  # the group on some lines only
     r"x.tsv:3: 7 columns, but the header \(line 1\) names 13: .*dir1..dir6, on every line"),
    (HEAD + GROUP + "\n" + LINE + "\t1\t-1\t0\n",  # a partial group on a line
     r"x.tsv:2: 10 columns, but the header \(line 1\) names 13"),
    (HEAD + "\tplate" + GROUP + "\n" + LINE + D6 + "\n",  # the plate missing
     r"x.tsv:2: 13 columns, but the header \(line 1\) names 14: q1..q6, Dm, plate and"),
    (HEAD + "\tdir1\tdir2\tdir3\n" + LINE + "\t1\t1\t1\n",  # a partial group in the header
     r"x.tsv:1: header columns after Dm must be plate and/or the whole direction group "
     r"dir1..dir6, found 'dir1 dir2 dir3'"),
    (HEAD + GROUP + "\tplate\n" + LINE + D6 + "\t1\n", r"x.tsv:1: header columns after Dm"),
    (LINE + D6 + "\n",  # no header: 13 columns are not read by position
     r"x.tsv:1: 13 columns without a header naming them: the direction columns dir1..dir6 "
     r"are read only under a header line"),
    (HEAD + "\n" + LINE + "\t2" + D6 + "\n", r"x.tsv:2: 14 columns without a header naming"),
])
def test_direction_group_refusals_name_file_and_line(tmp_path, content, message):
    p = tmp_path / "x.tsv"
    p.write_text(content)
    with pytest.raises(InputError, match=message):
        read_samples(p)
