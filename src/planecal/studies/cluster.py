"""Which Dask scheduler a study may use, checked before any connection, and the bounded
handshake with it.

A Dask scheduler runs whatever code a client sends it: whoever can reach its port can run
code on every worker. So planecal takes:

* ``tls://HOST:PORT``: dask's TLS with a CA of the cluster's own. The scheduler, every
  worker and every client show a certificate signed by that CA and check the other side's
  (mutual TLS); a client without one is refused at the handshake;
* ``tcp://HOST:PORT`` only for a scheduler on this machine: HOST a loopback address
  (127.0.0.0/8, ::1) or a name that resolves to loopback addresses only (``localhost``).
  Anywhere else plain tcp:// is refused in one line unless ``insecure`` (``--insecure``)
  says the user means a scheduler open to the network;
* nothing else: no scheme, another scheme, a port outside 1..65535 are one line too.

The certificates (``TLSFiles``: ``--tls-ca``, ``--tls-cert``, ``--tls-key``) or, without
them, dask's own configuration (``distributed.comm.tls.ca-file``, ``.client.cert``,
``.client.key``, e.g. from the environment ``planecal worker-env --tls-...`` prints).
``tls_env(files)`` gives that environment for the scheduler, worker and client roles, with
``distributed.comm.require-encryption`` on.

``probe(address, security, timeout_s)``: dask's connection handshake with the scheduler,
bounded as a whole. dask bounds the TCP connect but not the handshake's read: a server
that accepts and never answers held a client for ever, and an HTTP server's reply, read as
a frame length, asked for 3 EiB.
"""
from __future__ import annotations

import ipaddress
import re
import socket
import ssl
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

from planecal.base.errors import InputError

SCHEMES = ("tls", "tcp")
EXAMPLE = "tls://HOST:8786"
# dask's configuration keys of a TLS cluster (all roles share one certificate here)
TLS_KEYS = {"ca": ("distributed.comm.tls.ca-file",),
            "cert": tuple(f"distributed.comm.tls.{r}.cert" for r in ("scheduler", "worker",
                                                                     "client")),
            "key": tuple(f"distributed.comm.tls.{r}.key" for r in ("scheduler", "worker",
                                                                   "client"))}
REQUIRE_ENCRYPTION = "distributed.comm.require-encryption"
_ADDRESS = re.compile(r"(?P<scheme>[A-Za-z][A-Za-z0-9+.-]*)://"
                      r"(?P<host>\[[^\]/]*\]|[^:/\[\]]*)(?::(?P<port>[^/]*))?/?")


@dataclass(frozen=True)
class SchedulerAddress:
    scheme: str  # "tls" or "tcp"
    host: str  # a name or an IP address (IPv6 without brackets)
    port: int

    def __str__(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"{self.scheme}://{host}:{self.port}"


@dataclass(frozen=True)
class TLSFiles:
    """The cluster's CA certificate, and this machine's certificate and key (``key``
    None: the certificate file holds the key too). PEM files."""
    ca: Path
    cert: Path
    key: Path | None = None


def tls_files(ca, cert, key) -> TLSFiles | None:
    """``TLSFiles`` from the three options (None if none is given); each file must be
    readable. One-line InputError otherwise."""
    if ca is None and cert is None and key is None:
        return None
    if ca is None or cert is None:
        raise InputError("--tls-ca and --tls-cert go together (with --tls-key, unless the "
                         "certificate file holds the key)")
    files = TLSFiles(Path(ca).absolute(), Path(cert).absolute(),
                     None if key is None else Path(key).absolute())
    for flag, path in (("--tls-ca", files.ca), ("--tls-cert", files.cert),
                       ("--tls-key", files.key)):
        if path is not None and not path.is_file():
            raise InputError(f"{flag} {path}: no such file")
    return files


def tls_env(files: TLSFiles) -> dict[str, str]:
    """dask's configuration of a TLS cluster member (scheduler, worker and client alike),
    as ``{key: value}``."""
    out = {k: str(files.ca) for k in TLS_KEYS["ca"]}
    out |= {k: str(files.cert) for k in TLS_KEYS["cert"]}
    if files.key is not None:
        out |= {k: str(files.key) for k in TLS_KEYS["key"]}
    return out | {REQUIRE_ENCRYPTION: "True"}


def parse_address(text: str) -> SchedulerAddress:
    """``tls://HOST:PORT`` or ``tcp://HOST:PORT`` (module docstring); one-line InputError
    for anything else."""
    where = f"--scheduler {str(text)[:200]!r}"
    m = _ADDRESS.fullmatch(str(text).strip())
    if m is None:
        raise InputError(f"{where}: not a scheduler address (expected {EXAMPLE})")
    scheme = m["scheme"].lower()
    if scheme not in SCHEMES:
        raise InputError(f"{where}: {scheme}:// does not reach a Dask scheduler here "
                         f"(expected {EXAMPLE}, or tcp:// to one on this machine)")
    host, port = m["host"].strip("[]"), m["port"]
    if not host:
        raise InputError(f"{where}: no host (expected {EXAMPLE})")
    if port is None or not port.isdigit() or not 1 <= int(port) <= 65535:
        raise InputError(f"{where}: {'no port' if not port else repr(port) + ' is not a port'}"
                         f" (1 .. 65535; dask's default is 8786)")
    return SchedulerAddress(scheme, host, int(port))


def on_this_machine(addr: SchedulerAddress) -> bool:
    """True if every address the host resolves to is a loopback address."""
    try:
        return ipaddress.ip_address(addr.host).is_loopback
    except ValueError:  # a name
        pass
    try:
        infos = socket.getaddrinfo(addr.host, addr.port, type=socket.SOCK_STREAM)
    except socket.gaierror as e:
        raise InputError(f"--scheduler {addr}: cannot resolve {addr.host} ({e.strerror})") \
            from None
    except (OSError, UnicodeError) as e:
        raise InputError(f"--scheduler {addr}: cannot resolve {addr.host} ({e})") from None
    return all(ipaddress.ip_address(str(info[4][0]).split("%")[0]).is_loopback
               for info in infos)


def check_reach(addr: SchedulerAddress, insecure: bool) -> None:
    """A plain tcp:// scheduler off this machine only with ``insecure``."""
    if addr.scheme == "tls":
        if insecure:
            raise InputError("--insecure is for a plain tcp:// scheduler; a tls:// one needs "
                             "none")
        return
    if not insecure and not on_this_machine(addr):
        raise InputError(f"--scheduler {addr}: a plain tcp:// scheduler runs any code that "
                         "anyone who reaches its port sends; use tls:// with certificates "
                         "(README: a cluster of your machines), or --insecure if you mean it")


def client_security(addr: SchedulerAddress, files: TLSFiles | None):
    """The ``distributed.Security`` of a client of ``addr`` (None for tcp://): from
    ``files``, else from dask's configuration; its certificates loaded here, so a missing
    or broken one is one line before any connection."""
    if addr.scheme == "tcp":
        if files is not None:
            raise InputError("--tls-ca/--tls-cert/--tls-key: for a tls:// scheduler, not "
                             f"{addr}")
        return None
    from distributed import Security
    if files is not None:
        sec = Security(tls_ca_file=str(files.ca), tls_client_cert=str(files.cert),
                       tls_client_key=None if files.key is None else str(files.key),
                       require_encryption=True)
        source = "--tls-ca/--tls-cert/--tls-key"
    else:
        sec = Security()
        source = "dask's distributed.comm.tls settings"
        if not sec.tls_ca_file or not sec.tls_client_cert:
            raise InputError(f"--scheduler {addr}: no certificates for a TLS client; give "
                             "--tls-ca, --tls-cert and --tls-key, or export $(planecal "
                             "worker-env --tls-ca CA.pem --tls-cert CERT.pem --tls-key KEY.pem)")
    check_certificates(sec.tls_ca_file, sec.tls_client_cert, sec.tls_client_key, source)
    return sec


def check_certificates(ca: str, cert: str, key: str | None, source: str) -> None:
    """The CA, certificate and key loaded as ssl loads them; one line naming the file."""
    for what, path in (("CA", ca), ("certificate", cert), ("key", key)):
        if path is not None and "\n" not in path and not Path(path).is_file():
            raise InputError(f"{path}: TLS {what} ({source}): no such file")
    try:
        ctx = ssl.create_default_context(ssl.Purpose.SERVER_AUTH, cafile=ca)
    except (ssl.SSLError, OSError) as e:
        raise InputError(f"{ca}: not a PEM CA certificate ({source}; {e})") from None
    try:
        ctx.load_cert_chain(cert, key)
    except (ssl.SSLError, OSError) as e:
        raise InputError(f"{cert}{' + ' + key if key else ''}: not a PEM certificate and "
                         f"matching key ({source}; {e})") from None


def probe(addr: SchedulerAddress, security, timeout_s: float) -> None:
    """Dask's connection handshake with ``addr``, the whole of it within ``timeout_s``
    (module docstring); one-line InputError naming what went wrong."""
    import asyncio

    from distributed.comm import connect
    args = security.get_connection_args("client") if security is not None else {}

    async def handshake():  # dask's own connect bound first: its error names the cause
        comm = await connect(str(addr), timeout=0.75 * timeout_s, **args)
        await comm.close()

    def run():  # a loop of its own, in a thread of its own (the caller may be in a loop)
        asyncio.run(asyncio.wait_for(handshake(), timeout_s))

    with ThreadPoolExecutor(1, thread_name_prefix="planecal-probe") as ex:
        try:
            ex.submit(run).result()
        except (asyncio.TimeoutError, TimeoutError):
            raise InputError(f"--scheduler {addr}: no Dask scheduler answered within "
                             f"{timeout_s:g} s (TimeoutError)") from None
        except OSError as e:  # refused, reset, closed (dask's CommClosedError is one), TLS
            tls = _tls_failure(e)
            if tls:
                raise InputError(f"--scheduler {addr}: the TLS handshake failed ({tls}): "
                                 "scheduler and client need certificates from the same "
                                 "CA") from None
            raise InputError(f"--scheduler {addr}: no Dask scheduler answered within "
                             f"{timeout_s:g} s ({type(e).__name__})") from None
        except Exception as e:  # noqa: BLE001 - bytes of another protocol, read as dask's
            raise InputError(f"--scheduler {addr}: something answered, but not as a Dask "
                             f"scheduler ({type(e).__name__})") from None


def _tls_failure(e: OSError) -> str | None:
    """The reason of the TLS error behind ``e``, or None. dask wraps it in CommClosedError
    (the SSLError its cause), or, when the other side refused our certificate (an unknown
    CA), raises FatalCommClosedError with the SSL error only in its message."""
    from distributed.comm.core import FatalCommClosedError
    err: BaseException | None = e
    while err is not None:
        if isinstance(err, ssl.SSLError):
            return str(err)
        err = err.__cause__ or err.__context__
    if isinstance(e, FatalCommClosedError):
        m = re.search(r"\[SSL: [^\]]*\][^(]*", str(e))
        return m[0].strip() if m else str(e)
    return None
