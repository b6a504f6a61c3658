"""Checked inputs (issue 25): seeds and ports through one argparse type in every command
that takes them, refused in one line (exit 2) before any file or socket is made; --config
tables and keys that no command has are errors, not silently ignored."""
import argparse
import re

import pytest

from planecal.cli import COMMANDS, build_parser, main
from planecal.commands import value_options as V
from repo import repo_path

SEED = str(repo_path("examples", "seed_samples.tsv"))
TABLE10 = str(repo_path("examples", "table10_params.json"))
BAD_SEEDS = ["-1", str(2**63), "1.5", "x", "", "9" * 5000]
BAD_PORTS = ["65536", "-1", "80.5", "http", "9" * 5000]


# ----- the types ----------------------------------------------------------------------------

def test_seed_type_takes_0_to_2_63_minus_1():
    assert V.seed("0") == 0 and V.seed(" 7 ") == 7 and V.seed(str(2**63 - 1)) == 2**63 - 1
    for bad in BAD_SEEDS:
        with pytest.raises(argparse.ArgumentTypeError, match="is not a seed"):
            V.seed(bad)
    assert V.seed_list("0,1, 2,") == [0, 1, 2]
    for bad, why in [("0,0", "the seed 0 is given twice"), (",", "holds no seeds"),
                     ("1,-2", "-2 is not a seed")]:
        with pytest.raises(argparse.ArgumentTypeError, match=why):
            V.seed_list(bad)


def test_port_types():
    assert V.port("1") == 1 and V.port("65535") == 65535 and V.port_or_zero("0") == 0
    for bad in BAD_PORTS + ["0"]:
        with pytest.raises(argparse.ArgumentTypeError, match=r"is not a port \(1 \.\. 65535\)"):
            V.port(bad)
    with pytest.raises(argparse.ArgumentTypeError, match=r"is not a port \(0 \.\. 65535\)"):
        V.port_or_zero("65536")
    # a long number is shortened in the message
    with pytest.raises(argparse.ArgumentTypeError) as e:
        V.port("9" * 5000)
    assert len(str(e.value)) < 100


# ----- every command that takes one ------------------------------------------------------------

def _seed_cases(out):
    """(argv before the value, option): every seed option of every command."""
    return [
        (["rehearse", "--out", out], "--seed"),
        (["rehearse", "--out", out], "--twin-seed"),
        (["sample", "--rt", "127.0.0.1", "--laser", "/dev/null", "--out", out], "--seed"),
        (["emulate"], "--seed"),
        (["emulate"], "--fault-seed"),
        (["emulate"], "--drop-seed"),
        (["replay", SEED, "--params", TABLE10, "--out", out], "--truth-seed"),
        (["demo", "--dir", out], "--seed"),
        (["bootstrap", SEED, "--out", out], "--seed"),
        (["layouts", "--out", out], "--seed"),
        (["mjcf", "--out", out], "--truth-seed"),
        (["montecarlo", "--out", out], "--seed"),
        (["montecarlo", "--out", out], "--truth-seed"),
        (["plan", "--out", out], "--seed"),
        (["validate", "--out", out], "--seed"),
        (["validate", "--out", out], "--truth-seed"),
        (["validate", "--out", out], "--truth-seeds"),
    ]


def _port_cases(out):
    sample = ["sample", "--rt", "127.0.0.1", "--laser", "/dev/null", "--out", out]
    rehearse = ["rehearse", "--out", out]
    return [(sample, "--rt-port", BAD_PORTS + ["0"]), (sample, "--local-port", BAD_PORTS),
            (["emulate"], "--rt-port", BAD_PORTS), (["emulate"], "--reply-port", BAD_PORTS),
            *((argv, "--live-port", BAD_PORTS + ["0"]) for argv in (sample, rehearse)),
            *((argv, "--live-web-port", BAD_PORTS) for argv in (sample, rehearse))]


def _refused(argv, option, what, tmp_path, capsys):
    assert main(argv) == 2, argv
    err = capsys.readouterr().err
    command = argv[0]
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert re.match(rf"planecal {command}: error: argument [\w/-]*{option}\b[\w/-]*: ", err) and \
        re.search(what, err) and err.endswith(f"(see planecal {command} --help)\n"), err
    assert list(tmp_path.iterdir()) == []  # refused before anything was written


def test_every_seed_option_refuses_a_bad_seed_in_one_line(tmp_path, capsys):
    out = str(tmp_path / "out")
    for argv, option in _seed_cases(out):
        for bad in BAD_SEEDS:
            _refused(argv + [option, bad], option, "is not a seed|holds no seeds", tmp_path,
                     capsys)


def test_every_port_option_refuses_a_bad_port_in_one_line(tmp_path, capsys):
    out = str(tmp_path / "out")
    for argv, option, bads in _port_cases(out):
        for bad in bads:
            _refused(argv + [option, bad], option, r"is not a port \(", tmp_path, capsys)


def test_every_seed_and_port_option_uses_the_shared_type(capsys):
    """No command takes a seed or a port through another type (a new option included):
    argparse converts a value as it reads it, before it checks for missing options."""
    parser = build_parser([], full=True)
    found = set()
    for name, p in parser.commands.items():
        for option in sorted(p.long_options):
            if re.search(r"(^|-)(seeds?|port)$", option):
                found.add((name, option))
                assert main([name, f"--{option}", "x"]) == 2
                kind = "port" if option.endswith("port") else "seed"
                assert f"'x' is not a {kind} (" in capsys.readouterr().err, (name, option)
    assert {(c, o.lstrip("-")) for argv, o in _seed_cases("x") for c in argv[:1]} | \
        {(argv[0], o.lstrip("-")) for argv, o, _ in _port_cases("x")} == found


def test_the_largest_seed_runs(tmp_path, capsys):
    out = tmp_path / "r.tsv"
    assert main(["rehearse", "--seed", str(2**63 - 1), "--samples", "2", "--out", str(out),
                 "-q"]) == 0
    assert '"samples": 2' in capsys.readouterr().out


# ----- --config --------------------------------------------------------------------------------

def _config(tmp_path, text):
    cfg = tmp_path / "c.toml"
    cfg.write_text(text)
    return cfg


@pytest.mark.parametrize("text, message", [
    ("[calibrat]\nmax-iter = 3\n",
     "[calibrat]: no such command (the tables are commands: bootstrap, calibrate, "),
    ("[rehearse]\nsamples = 3\n[montecarl]\nruns = 2\n", "[montecarl]: no such command"),
    ("samples = 3\n", "samples: an option outside a [command] table"),
    ("rehearse = 3\n", "[rehearse] must be a table of options"),
    ("[rehearse]\nsamplez = 3\n", "[rehearse].samplez: planecal rehearse has no option "
                                  "--samplez (the keys are its long option names, in full; "
                                  "see planecal rehearse --help)"),
    ("[rehearse]\nsamp = 3\n", "[rehearse].samp: planecal rehearse has no option --samp"),
    ("[rehearse]\nforse = false\n", "[rehearse].forse: planecal rehearse has no option"),
    ("[rehearse]\nv = 1\n", "[rehearse].v: planecal rehearse has no option --v"),
    ("[rehearse]\nseed = -1\n", "argument --seed: -1 is not a seed"),
])
def test_config_tables_and_keys_no_command_has_are_errors(tmp_path, capsys, text, message):
    cfg = _config(tmp_path, text)
    out = tmp_path / "r.tsv"
    assert main(["rehearse", "--config", str(cfg), "--out", str(out), "--samples", "2"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and str(cfg) in err and message in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.toml"]


def test_config_with_tables_of_other_commands_and_underscored_keys(tmp_path, capsys):
    truth = tmp_path / "t.json"
    cfg = _config(tmp_path, f'[rehearse]\nsamples = 2\ntruth_out = "{truth}"\nforce = false\n'
                            '[calibrate]\nmax-iter = 3\n[validate]\ntruth-seeds = "0,1"\n')
    out = tmp_path / "r.tsv"
    assert main(["rehearse", "--config", str(cfg), "--out", str(out), "-q"]) == 0
    import json
    assert json.loads(capsys.readouterr().out)["samples"] == 2
    assert truth.exists()  # truth_out: the option --truth-out


def test_every_long_option_is_known_to_the_config_check(capsys):
    """The parser records every long option a command has (argument groups and mutually
    exclusive groups included): each one --help shows."""
    parser = build_parser([], full=True)
    for name in COMMANDS:
        p = parser.commands[name]
        shown = set(re.findall(r"(?<![\w-])--([a-z][a-z0-9-]*)", p.format_usage()))
        assert shown <= p.long_options | {"help"}, (name, shown - p.long_options)
        assert {"config", "verbose", "quiet", "help"} <= p.long_options
