"""Studies on a cluster only its owners can use (issue 25): a Monte Carlo study on a TLS
scheduler with two TLS workers, certificates made here (a CA of the test's own), gives
the --jobs 1 numbers; a client without a certificate from that CA is refused; scheduler
addresses are checked before any connection (plain tcp:// only on this machine unless
--insecure), and dask's handshake is bounded as a whole."""
import datetime
import http.server
import json
import os
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from planecal.base.errors import InputError
from planecal.cli import main
from planecal.studies import cluster as C
from planecal.studies import distributed as D

BIN = Path(sys.executable).parent
MC_ARGS = ["montecarlo", "--mode", "synthetic", "--runs", "4", "--samples", "30", "--seed",
           "5"]


# ----- certificates ---------------------------------------------------------------------------

def make_ca(d: Path, name: str):
    """A CA of its own: (certificate path, key, certificate)."""
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import NameOID
    key = ec.generate_private_key(ec.SECP256R1())
    subject = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, name)])
    now = datetime.datetime.now(datetime.timezone.utc)
    cert = (x509.CertificateBuilder().subject_name(subject).issuer_name(subject)
            .public_key(key.public_key()).serial_number(x509.random_serial_number())
            .not_valid_before(now - datetime.timedelta(minutes=5))
            .not_valid_after(now + datetime.timedelta(days=1))
            .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
            .add_extension(x509.KeyUsage(digital_signature=True, key_cert_sign=True,
                                         crl_sign=True, content_commitment=False,
                                         key_encipherment=False, data_encipherment=False,
                                         key_agreement=False, encipher_only=False,
                                         decipher_only=False), critical=True)
            .sign(key, hashes.SHA256()))
    path = d / f"{name}.pem"
    path.write_bytes(cert.public_bytes(serialization.Encoding.PEM))
    return path, key, cert


def make_member(d: Path, ca, name: str) -> C.TLSFiles:
    """A certificate and key signed by ``ca`` for a cluster member on 127.0.0.1 (the
    scheduler, the workers and the client share it, as the README's set-up does)."""
    import ipaddress

    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import NameOID
    ca_path, ca_key, ca_cert = ca
    key = ec.generate_private_key(ec.SECP256R1())
    now = datetime.datetime.now(datetime.timezone.utc)
    cert = (x509.CertificateBuilder()
            .subject_name(x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, name)]))
            .issuer_name(ca_cert.subject).public_key(key.public_key())
            .serial_number(x509.random_serial_number())
            .not_valid_before(now - datetime.timedelta(minutes=5))
            .not_valid_after(now + datetime.timedelta(days=1))
            .add_extension(x509.SubjectAlternativeName(
                [x509.IPAddress(ipaddress.ip_address("127.0.0.1"))]), critical=False)
            .sign(ca_key, hashes.SHA256()))
    cert_path, key_path = d / f"{name}.pem", d / f"{name}-key.pem"
    cert_path.write_bytes(cert.public_bytes(serialization.Encoding.PEM))
    key_path.write_bytes(key.private_bytes(serialization.Encoding.PEM,
                                           serialization.PrivateFormat.PKCS8,
                                           serialization.NoEncryption()))
    key_path.chmod(0o600)
    return C.TLSFiles(ca_path, cert_path, key_path)


def tls_flags(f: C.TLSFiles) -> list[str]:
    return ["--tls-ca", str(f.ca), "--tls-cert", str(f.cert), "--tls-key", str(f.key)]


@pytest.fixture(scope="module")
def certs(tmp_path_factory):
    d = tmp_path_factory.mktemp("certs")
    ours, theirs = make_ca(d, "cluster-ca"), make_ca(d, "other-ca")
    return {"member": make_member(d, ours, "member"),
            "stranger": make_member(d, theirs, "stranger"),  # another CA's certificate
            "other_ca": theirs[0]}


def worker_env(files: C.TLSFiles) -> dict:
    """``export $(planecal worker-env --tls-...)``: the environment it prints."""
    p = subprocess.run([str(BIN / "planecal"), "worker-env", *tls_flags(files)],
                       capture_output=True, text=True, timeout=60)
    assert p.returncode == 0, p.stderr
    return dict(line.split("=", 1) for line in p.stdout.split())


def _stop(procs):
    for p in procs:
        if p.poll() is None:
            p.terminate()
    for p in procs:
        try:
            p.wait(timeout=20)
        except subprocess.TimeoutExpired:
            p.kill()  # the process this test started
            p.wait(timeout=10)


@pytest.fixture(scope="module")
def tls_cluster(certs, tmp_path_factory):
    """The README's TLS set-up on 127.0.0.1: `dask scheduler` with the certificates as
    flags, two `dask worker`s with them from `planecal worker-env`'s environment only.
    Bounded waits; stopped at the end of the module whatever happened."""
    d = tmp_path_factory.mktemp("tls-dask")
    f = certs["member"]
    env = {**os.environ, **worker_env(f)}
    sfile = d / "scheduler.json"
    log = open(d / "dask.log", "w")
    procs = [subprocess.Popen(
        [str(BIN / "dask"), "scheduler", "--protocol", "tls", "--host", "127.0.0.1",
         "--port", "0", "--tls-ca-file", str(f.ca), "--tls-cert", str(f.cert),
         "--tls-key", str(f.key), "--no-dashboard", "--dashboard-address", "127.0.0.1:0",
         "--scheduler-file", str(sfile)], stdout=log, stderr=log, env=env)]
    try:
        deadline = time.monotonic() + 60
        while not sfile.exists() or not sfile.read_text().strip():
            assert time.monotonic() < deadline, "the scheduler did not start within 60 s"
            assert procs[0].poll() is None, (d / "dask.log").read_text()
            time.sleep(0.2)
        addr = json.loads(sfile.read_text())["address"]
        assert addr.startswith("tls://127.0.0.1:")
        for _ in range(2):
            procs.append(subprocess.Popen(
                [str(BIN / "dask"), "worker", addr, "--nthreads", "1", "--no-dashboard",
                 "--host", "127.0.0.1", "--dashboard-address", "127.0.0.1:0"],
                stdout=log, stderr=log, env=env))
        with D.Engine(scheduler=addr, tls=f, connect_timeout_s=60) as eng:
            eng.client.wait_for_workers(2, timeout=60)
        yield addr, env
    finally:
        _stop(procs[1:])
        _stop(procs[:1])
        log.close()


# ----- the study on the TLS cluster --------------------------------------------------------------

def _mc(out: Path, *extra) -> dict:
    assert main(MC_ARGS + ["--out", str(out), *extra]) == 0
    return json.loads(out.read_text())


def test_montecarlo_on_a_tls_cluster_gives_the_jobs_1_numbers(tls_cluster, certs, tmp_path,
                                                              capsys):
    addr, env = tls_cluster
    here = _mc(tmp_path / "jobs1.json", "--jobs", "1")
    capsys.readouterr()
    there = _mc(tmp_path / "tls.json", "--scheduler", addr, *tls_flags(certs["member"]))
    err = capsys.readouterr().err
    # both workers have planecal's settings (the TLS environment carries them too)
    assert f"Dask scheduler {addr}: 2 worker threads;" in err and "note:" not in err, err
    assert len(here["run_errors"]) == 4 and there["run_errors"] == here["run_errors"]
    assert there == here
    # the certificates from the environment alone (dask's settings), as a shell that ran
    # export $(planecal worker-env --tls-...) runs it
    out = tmp_path / "env.json"
    p = subprocess.run([str(BIN / "planecal"), *MC_ARGS, "--scheduler", addr, "--out",
                        str(out), "-q"], capture_output=True, text=True, env=env, timeout=300)
    assert p.returncode == 0, p.stderr
    assert json.loads(out.read_text()) == here


def test_a_client_without_the_clusters_certificate_is_refused(tls_cluster, certs):
    addr, _ = tls_cluster
    # no certificate at all: refused before any connection
    t0 = time.monotonic()
    with pytest.raises(InputError, match="no certificates for a TLS client; give --tls-ca"):
        D.Engine(scheduler=addr)
    assert time.monotonic() - t0 < 5
    # a certificate of another CA (trusting the cluster's CA): the scheduler refuses it
    s = certs["stranger"]
    # (either side may notice first, each time: several tries)
    for files in [C.TLSFiles(certs["member"].ca, s.cert, s.key),  # we trust them, not they us
                  C.TLSFiles(certs["other_ca"], certs["member"].cert, certs["member"].key)] * 4:
        t0 = time.monotonic()
        with pytest.raises(InputError) as e:
            with D.Engine(scheduler=addr, tls=files, connect_timeout_s=3):
                pass
        assert time.monotonic() - t0 < 10
        msg = str(e.value)
        assert msg.startswith(f"--scheduler {addr}: the TLS handshake failed (") and \
            msg.endswith("): scheduler and client need certificates from the same CA"), msg
    # plain tcp:// to the TLS port
    plain = addr.replace("tls://", "tcp://")
    with pytest.raises(InputError, match=f"--scheduler {plain}: no Dask scheduler answered "
                                         r"within 3 s \(\w+\)"):
        with D.Engine(scheduler=plain, connect_timeout_s=3):
            pass


def test_a_tls_refusal_is_named_however_dask_reports_it():
    """dask reports the other side's refusal of our certificate as FatalCommClosedError
    with the SSL error only in its message; our own refusal of theirs as CommClosedError
    caused by the SSLError."""
    import ssl

    from distributed.comm.core import CommClosedError, FatalCommClosedError
    fatal = FatalCommClosedError("in <TLSConnector>: SSLError: [SSL: TLSV1_ALERT_UNKNOWN_CA] "
                                 "tlsv1 alert unknown ca (_ssl.c:2580)")
    assert C._tls_failure(fatal) == "[SSL: TLSV1_ALERT_UNKNOWN_CA] tlsv1 alert unknown ca"
    try:
        try:
            raise ssl.SSLCertVerificationError(1, "[SSL: CERTIFICATE_VERIFY_FAILED] ...")
        except ssl.SSLError as e:
            raise CommClosedError("in <TLSConnector>: closed") from e
    except CommClosedError as e:
        assert "CERTIFICATE_VERIFY_FAILED" in C._tls_failure(e)
    assert C._tls_failure(CommClosedError("in <TCPConnector>: closed")) is None


# ----- planecal worker-env ---------------------------------------------------------------------

def test_worker_env_gives_dasks_tls_settings(certs, tmp_path):
    f = certs["member"]
    env = worker_env(f)
    tls = {k: v for k, v in env.items() if "TLS" in k or "ENCRYPTION" in k}
    assert tls == {"DASK_DISTRIBUTED__COMM__TLS__CA_FILE": str(f.ca),
                   **{f"DASK_DISTRIBUTED__COMM__TLS__{r}__{k.upper()}": str(getattr(f, k))
                      for r in ("SCHEDULER", "WORKER", "CLIENT") for k in ("cert", "key")},
                   "DASK_DISTRIBUTED__COMM__REQUIRE_ENCRYPTION": "True"}
    # the installed dask reads them as its own settings
    keys = ["distributed.comm.tls.ca-file", "distributed.comm.tls.worker.cert",
            "distributed.comm.tls.scheduler.key", "distributed.comm.tls.client.cert",
            "distributed.comm.require-encryption"]
    p = subprocess.run([sys.executable, "-c", "import dask, json, sys; print(json.dumps("
                        f"[dask.config.get(k) for k in {keys!r}]))"],
                       capture_output=True, text=True, env={**os.environ, **env}, timeout=60)
    assert json.loads(p.stdout) == [str(f.ca), str(f.cert), str(f.key), str(f.cert), True]
    # a missing file, a file that is not PEM, a blank in a path: one line, exit 2
    bad = tmp_path / "notpem.pem"
    bad.write_text("hello\n")
    spaced = tmp_path / "a b"
    spaced.mkdir()
    (spaced / "ca.pem").write_bytes(f.ca.read_bytes())
    for flags, message in [
        (["--tls-ca", str(tmp_path / "nope.pem"), "--tls-cert", str(f.cert)],
         f"--tls-ca {tmp_path / 'nope.pem'}: no such file"),
        (["--tls-ca", str(bad), "--tls-cert", str(f.cert)], f"{bad}: not a PEM CA certificate"),
        (["--tls-ca", str(f.ca), "--tls-cert", str(f.cert), "--tls-key",
          str(certs["stranger"].key)], "not a PEM certificate and matching key"),
        (["--tls-ca", str(f.ca)], "--tls-ca and --tls-cert go together"),
        (["--tls-ca", str(spaced / "ca.pem"), "--tls-cert", str(f.cert), "--tls-key",
          str(f.key)], "a path with a blank cannot pass through export"),
    ]:
        p = subprocess.run([str(BIN / "planecal"), "worker-env", *flags], capture_output=True,
                           text=True, timeout=60)
        assert p.returncode == 2 and p.stdout == "", (flags, p.stdout)
        assert p.stderr.count("\n") == 1 and message in p.stderr, (flags, p.stderr)


# ----- addresses, before any connection ----------------------------------------------------------

@pytest.mark.parametrize("address, message", [
    ("localhost", "--scheduler 'localhost': not a scheduler address (expected tls://HOST:8786)"),
    ("udp://127.0.0.1:8786", "--scheduler 'udp://127.0.0.1:8786': udp:// does not reach a "
                             "Dask scheduler here"),
    ("http://127.0.0.1:8787", "http:// does not reach a Dask scheduler here"),
    ("tls://:8786", "--scheduler 'tls://:8786': no host"),
    ("tls://10.0.0.5", "--scheduler 'tls://10.0.0.5': no port (1 .. 65535"),
    ("tls://10.0.0.5:0", "'0' is not a port (1 .. 65535"),
    ("tcp://127.0.0.1:65536", "'65536' is not a port (1 .. 65535"),
    ("tcp://127.0.0.1:-1", "'-1' is not a port"),
    ("tcp://192.0.2.7:8786", "--scheduler tcp://192.0.2.7:8786: a plain tcp:// scheduler runs "
                             "any code that anyone who reaches its port sends; use tls:// "
                             "with certificates (README: a cluster of your machines), or "
                             "--insecure if you mean it"),
    ("tcp://[2001:db8::1]:8786", "a plain tcp:// scheduler runs any code"),
    ("tcp://no-such-host.invalid:8786", "cannot resolve no-such-host.invalid"),
])
def test_bad_scheduler_addresses_are_one_line_before_any_connection(address, message):
    t0 = time.monotonic()
    with pytest.raises(InputError) as e:
        D.Engine(scheduler=address)
    assert message in str(e.value) and "\n" not in str(e.value)
    assert time.monotonic() - t0 < 5  # no connection tried


def test_which_addresses_count_as_this_machine():
    for host in ("127.0.0.1", "127.3.4.5", "::1", "localhost"):
        assert C.on_this_machine(C.SchedulerAddress("tcp", host, 8786)), host
    for host in ("192.0.2.7", "10.0.0.1", "2001:db8::1", "0.0.0.0"):
        assert not C.on_this_machine(C.SchedulerAddress("tcp", host, 8786)), host
    assert str(C.parse_address(" TCP://[::1]:8786 ")) == "tcp://[::1]:8786"
    # --insecure lets a plain tcp:// scheduler off this machine through to the connection
    with pytest.raises(InputError, match="no Dask scheduler answered within 1 s"):
        with D.Engine(scheduler="tcp://192.0.2.7:8786", insecure=True, connect_timeout_s=1):
            pass
    with pytest.raises(InputError, match="--insecure is for a plain tcp:// scheduler"):
        D.Engine(scheduler="tls://127.0.0.1:8786", insecure=True)
    with pytest.raises(InputError, match="are for --scheduler"):
        D.Engine(jobs=1, insecure=True)


def _server(reply: bytes | None):
    """A TCP server on 127.0.0.1 that accepts and sends ``reply`` (None: nothing, ever)."""
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen()
    held = []

    def serve():
        while True:
            try:
                c, _ = srv.accept()
            except OSError:
                return
            held.append(c)
            if reply is not None:
                c.sendall(reply)

    threading.Thread(target=serve, daemon=True).start()
    return srv, held


def test_a_server_that_is_no_scheduler_is_one_bounded_line():
    silent, held = _server(None)
    talker, held2 = _server(b"HTTP/1.1 400 Bad Request\r\nContent-Length: 0\r\n\r\n" * 4)
    web = http.server.ThreadingHTTPServer(("127.0.0.1", 0), _QuietHandler)
    threading.Thread(target=web.serve_forever, daemon=True).start()
    try:
        for port, why in [(silent.getsockname()[1], "no Dask scheduler answered within 2 s"),
                          (talker.getsockname()[1], "something answered, but not as a Dask "
                                                    "scheduler (MemoryError)"),
                          (web.server_address[1], "within 2 s")]:
            t0 = time.monotonic()
            with pytest.raises(InputError) as e:
                with D.Engine(scheduler=f"tcp://127.0.0.1:{port}", connect_timeout_s=2):
                    pass
            assert why in str(e.value), str(e.value)
            assert time.monotonic() - t0 < 6
    finally:
        silent.close()
        talker.close()
        web.shutdown()
        web.server_close()  # (waits for its handlers: none outlives the test)
        for c in held + held2:
            c.close()


class _QuietHandler(http.server.BaseHTTPRequestHandler):
    """A web server's handler that logs nothing: a request handled late (a loaded
    machine) wrote its log line into the next test's captured stderr."""

    def log_message(self, *args):
        pass


def test_study_commands_refuse_bad_schedulers_in_one_line(tmp_path, capsys):
    """Exit 2, one line, nothing written; a scheduler that accepts and never answers gives
    up within the documented 10 s (studies.distributed.CONNECT_TIMEOUT_S)."""
    out = str(tmp_path / "mc.json")
    silent, held = _server(None)
    cases = [(["--scheduler", "localhost"], "not a scheduler address"),
             (["--scheduler", "udp://127.0.0.1:8786"], "udp:// does not reach"),
             (["--scheduler", "tcp://192.0.2.7:8786"], "or --insecure if you mean it"),
             (["--scheduler", "tls://127.0.0.1:8786", "--insecure"], "--insecure is for"),
             (["--tls-ca", __file__, "--tls-cert", __file__], "are for --scheduler"),
             (["--scheduler", "tcp://127.0.0.1:8786", "--tls-ca", __file__, "--tls-cert",
               __file__], "for a tls:// scheduler, not tcp://127.0.0.1:8786"),
             (["--scheduler", f"tcp://127.0.0.1:{silent.getsockname()[1]}"],
              "no Dask scheduler answered within 10 s (TimeoutError)")]
    try:
        for extra, message in cases:
            t0 = time.monotonic()
            assert main(MC_ARGS + ["--out", out, *extra]) == 2, extra
            err = capsys.readouterr().err
            assert err.count("\n") == 1 and message in err, (extra, err)
            assert time.monotonic() - t0 < D.CONNECT_TIMEOUT_S + 5
            assert list(tmp_path.iterdir()) == []
    finally:
        silent.close()
        for c in held:
            c.close()
