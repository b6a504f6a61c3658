"""Issue 4, item 2: the same sampling run over the real wire formats (FD11 UDP, ZS-LD80 on
a pseudo-terminal, both emulators backed by the twin) gives the same samples as the
in-process twin."""
import numpy as np

from planecal.cli import main
from planecal.twin.world import WorldRef, make_twin
from planecal.links.emulators import Emulators
from planecal.io.samples import read_samples
from planecal.model.scene import load_scene
from wire import sample_argv


def test_sample_over_udp_and_serial_equals_rehearsal_in_process(tmp_path, capsys):
    common = ["--samples", "4", "--seed", "5", "--foreground"]
    local = tmp_path / "local.tsv"
    assert main(["rehearse", "--out", str(local), "--twin-seed", "7", *common]) == 0
    wire = tmp_path / "wire.tsv"
    twin = make_twin(load_scene("thesis_final"), WorldRef("realistic", 7), 7)  # rehearse's default world
    with Emulators(twin, rt_port=0, reply_port=None) as emu:
        code = main(sample_argv(emu.fd11.rt_port, emu.laser.port, wire, *common))
        assert not emu.fd11.tripped
    capsys.readouterr()
    assert code == 0
    a, b = read_samples(local), read_samples(wire)
    assert len(a) == len(b) == 4
    np.testing.assert_array_equal(a.qe, b.qe)  # same poses, same counts
    # same readings: the serial frame carries 1e-6 mm, the sample file 1e-6 mm, and the
    # twin draws its laser noise on the same ticks either way
    np.testing.assert_array_equal(a.d_mm, b.d_mm)
    # the same approach directions (issue 22): `sample` follows the counts the FD11's
    # replies carry as `rehearse` follows the twin's, through the same driver
    assert a.direction is not None and np.all(a.direction != 0)
    np.testing.assert_array_equal(a.direction, b.direction)
