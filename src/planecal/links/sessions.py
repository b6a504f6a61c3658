"""The FD11's client sessions: what the controller does with its reference between them,
what planecal recorded of the last one, and what a new session's first packet must be.

Why it matters (appendix C; issue 25)
-------------------------------------
Every packet carries a delta, and the controller commands ``reference + delta``. Within a
client session the reference is constant. Across sessions the seed leaves it open
(7.1.1: "the FD11 reference will represent the robot's initial encoder position when
application is booted up"): a controller that *keeps* its reference still holds the last
delta it received, so a new session's first packet must repeat it; a controller that
takes a *fresh* reference (the robot's counts) holds delta 0, so the first packet must be
0. Each first packet is a jump of the last delta under the other behaviour -- tens of
thousands of counts against a trip step of 60. planecal therefore never guesses: the
behaviour is a stated property of the cell, and where it is not stated a session that
cannot tell asks (`plan_contact`).

The behaviours (``robot.json`` ``controller.sessions``, docs/FORMATS.md; the same words
for ``planecal emulate --reference``):

* ``keep``: the reference is kept across client sessions (fixed when the RT system
  boots). A new session's first packet repeats the last delta the controller received.
* ``fresh_after_silence`` (with ``silence_s``): a request that comes after at least
  ``silence_s`` seconds without any takes the robot's current counts as the new
  reference, whichever client sends it. A new session waits until the controller has
  been silent for ``silence_s`` + `SILENCE_MARGIN_S` (using the time of the last packet,
  from the state file) and sends delta 0. A controller that also takes a new reference for
  a new client address is the same case for planecal: the wait makes the reference fresh
  either way.
* ``fresh_each_client``: a request from a client address (IP and UDP port) other than the
  last request's takes a new reference; the same address continues the session however
  long the silence. A new session from another address sends 0; from the same address it
  repeats the last delta.

The state file (`StateFile`)
----------------------------
One line per controller, rewritten in place at every packet: the last delta sent to the
controller in a session it has answered (the first packet of a session only once
answered), its reference counts then, the time the last packet was sent (UNIX
milliseconds, written just before each send, so a kill can only make the recorded
silence shorter than the real one) and the client address of the session::

    fd11-state/2 +0000000050 ... -0000000050 0008388608 ... 0008388608 1764000000123 \
        127.0.0.1:5556 crc32=1a2b3c4d

It is the controller's memory, not a run's: every run against that controller reads it
(a new run as much as a resume), so it lives in one place per controller,
``$PLANECAL_STATE_DIR`` (default ``$XDG_STATE_HOME/planecal``, i.e.
``~/.local/state/planecal``) as ``fd11-<ip>-<port>.state``, or where ``--rt-state`` says.
It is created at the first packet sent, never before. A line of the older format
``fd11-last-delta/1`` (a delta only) is read with the time and client unknown.
"""
from __future__ import annotations

import os
import socket
import time
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from planecal.base.errors import InputError
from planecal.formats.robot import REFERENCE_BEHAVIOURS
from planecal.links.errors import LinkError

N_JOINTS = 6
INT32_MAX = 2**31 - 1
BEHAVIOURS = REFERENCE_BEHAVIOURS  # keep, fresh_after_silence, fresh_each_client
# a new session waits this much beyond the controller's silence: the delay between the
# time written and the packet sent (scheduler latency on a loaded PC), and clock ticks
SILENCE_MARGIN_S = 0.5
STATE_TAG = b"fd11-state/2"
OLD_TAG = b"fd11-last-delta/1"
MAX_STATE_BYTES = 512


@dataclass(frozen=True)
class SessionBehaviour:
    """What the controller does with its reference between client sessions (module doc)."""
    reference: str
    silence_s: float | None = None
    source: str = "robot.json"  # where it is stated (for messages)

    def __post_init__(self):
        if self.reference not in BEHAVIOURS:
            raise ValueError(f"reference behaviour must be one of {BEHAVIOURS}, "
                             f"got {self.reference!r}")
        if (self.reference == "fresh_after_silence") != (self.silence_s is not None):
            raise ValueError("silence_s goes with fresh_after_silence, and only with it")
        if self.silence_s is not None and not 0 < self.silence_s < float("inf"):
            raise ValueError(f"silence_s must be a positive number, got {self.silence_s}")

    def describe(self) -> str:
        if self.reference == "fresh_after_silence":
            return f"takes a new reference after {self.silence_s:g} s of silence"
        return {"keep": "keeps its reference across client sessions",
                "fresh_each_client": "takes a new reference at each new client address"
                }[self.reference]


def stated_behaviour(robot_file: str | Path | None) -> SessionBehaviour | None:
    """The behaviour ``robot.json`` states in ``controller.sessions``; None when unstated
    (or when the robot has no file)."""
    if robot_file is None:
        return None
    from planecal.formats.base import read_json, validate
    from planecal.formats.robot import RobotFile

    rf = validate(RobotFile, read_json(robot_file, "robot description"), robot_file,
                  "robot description")
    s = rf.controller.sessions
    if s is None:
        return None
    return SessionBehaviour(s.reference, s.silence_s, f"{robot_file} controller.sessions")


@dataclass(frozen=True)
class LastSession:
    """What the state file recorded: the last delta sent in an answered session (wire frame),
    its reference then (None before any answer), when the last packet was sent (UNIX
    seconds; None: unknown) and from which client address ("ip:port"; None: unknown)."""
    path: Path
    delta: np.ndarray
    reference: np.ndarray | None
    sent_at: float | None
    client: str | None


@dataclass(frozen=True)
class Contact:
    """What the controller holds when a session's first packet arrives, as the stated
    behaviour (or the operator's ``--rt-fresh``/``--rt-keep``) says.

    ``kind``: "fresh" (a new reference: it holds delta 0), "kept" (it holds ``held``, the
    last delta it received) or "either" (nothing recorded, or the last delta was 0: both
    behaviours agree on a first packet of 0). ``held``: the delta the first packet is
    measured against (the link refuses a first packet farther than the step limit from it,
    and sends ``held`` itself as the first packet). ``reference``: the counts a kept
    reference must show in the first reply (None: not checked). ``wait_s``: the silence
    still to keep before the first packet. ``why``: the reason, for messages."""
    kind: str
    held: np.ndarray
    reference: np.ndarray | None = None
    wait_s: float = 0.0
    why: str = ""

    @classmethod
    def fresh(cls, why: str = "a fresh reference", wait_s: float = 0.0) -> "Contact":
        return cls("fresh", np.zeros(N_JOINTS, np.int64), None, wait_s, why)

    @classmethod
    def either(cls, why: str = "no earlier session recorded") -> "Contact":
        return cls("either", np.zeros(N_JOINTS, np.int64), None, 0.0, why)

    @classmethod
    def kept(cls, last: LastSession, why: str) -> "Contact":
        return cls("kept", last.delta.copy(), None if last.reference is None
                   else last.reference.copy(), 0.0, why)

    def describe(self) -> str:
        return {"fresh": "a fresh reference (first delta 0)",
                "kept": f"a kept reference (first delta {self.held.tolist()}, the last it "
                        f"received)",
                "either": "first delta 0 (both behaviours agree)"}[self.kind] + f": {self.why}"


def _silence_wait(behaviour: SessionBehaviour, last: LastSession | None, now: float) -> float:
    """What is left of a ``fresh_after_silence`` controller's silence and its margin since
    the last packet recorded (all of it when the time is unknown or the clock went back)."""
    need = behaviour.silence_s + SILENCE_MARGIN_S
    sent_at = None if last is None else last.sent_at
    silent = now - sent_at if sent_at is not None else 0.0
    wait = need - silent if 0.0 <= silent < need else (need if silent < 0 else 0.0)
    return round(wait, 3)


def plan_contact(behaviour: SessionBehaviour | None, last: LastSession | None,
                 override: str | None, client: str, now: float | None = None,
                 where: str = "robot.json", lost: str | None = None) -> Contact:
    """The first contact of a new session (module doc). ``override``: "fresh" or "keep",
    the operator's statement for this run (``--rt-fresh``, ``--rt-keep``), which wins over
    the cell's; a fresh reference on a cell that takes one only after a silence still
    waits that silence out (from the time of the last packet recorded: all of it when
    unknown), so the first packet of 0 is never measured from the old reference.
    ``client``: this link's address ("ip:port"). ``lost``: where an earlier session with
    this controller is recorded although ``last`` is None (a resumed run's sidecar whose
    state file is missing: another $PLANECAL_STATE_DIR, another user). Raises
    `InputError` (exit 2) when the behaviour is unstated (in ``where``, the robot file)
    and the controller was last left at a delta other than 0, or when the record of the
    last session is lost: planecal cannot tell which first packet is safe, so it asks."""
    now = time.time() if now is None else now
    if override == "fresh":
        why = "--rt-fresh: the controller took a fresh reference"
        if behaviour is not None and behaviour.reference == "fresh_after_silence" and (
                last is not None or lost):
            return Contact.fresh(f"{why}; {behaviour.source}: it {behaviour.describe()}",
                                 wait_s=_silence_wait(behaviour, last, now))
        return Contact.fresh(why)
    if last is None and lost:
        raise InputError(
            f"{lost} records an earlier session with this controller, but its state file "
            f"(the last delta it holds) is not here: planecal will not guess what the "
            f"controller holds; state for this run that it took a fresh reference "
            f"(--rt-fresh, e.g. the RT system was restarted), or give its state file "
            f"(--rt-state) so that --rt-keep can repeat the delta it kept")
    if override == "keep":
        if last is None:
            return Contact.either("--rt-keep, but no earlier session recorded")
        return Contact.kept(last, f"--rt-keep: the controller kept its reference ({last.path})")
    if last is None:
        return Contact.either("no earlier session recorded for this controller")
    if behaviour is None:
        if not last.delta.any():
            return Contact.either(f"the last delta recorded is 0 ({last.path})")
        raise InputError(
            f"{where}: controller.sessions is not stated (what the controller does with its "
            f"reference between client sessions), and it was last left at delta "
            f"{last.delta.tolist()} ({last.path}): "
            f"planecal will not guess whether the first packet must repeat it; state for "
            f"this run that the controller took a fresh reference (--rt-fresh) or kept it "
            f"(--rt-keep)")
    if behaviour.reference == "keep":
        return Contact.kept(last, f"{behaviour.source}: the controller {behaviour.describe()}")
    if behaviour.reference == "fresh_after_silence":
        # unknown time, or a clock that went back: wait the whole silence
        return Contact.fresh(f"{behaviour.source}: the controller {behaviour.describe()}",
                             wait_s=_silence_wait(behaviour, last, now))
    if last.client is None:
        raise InputError(f"{last.path}: records no client address (an older state line): "
                         f"state for this run that the controller took a fresh reference "
                         f"(--rt-fresh) or kept it (--rt-keep)")
    if last.client != client:
        return Contact.fresh(f"{behaviour.source}: the controller {behaviour.describe()} "
                             f"(this client {client}, the last {last.client})")
    return Contact.kept(last, f"{behaviour.source}: the controller {behaviour.describe()} "
                              f"(the same client address {client})")


def client_address(remote: tuple[str, int], local_port: int, bind_host: str) -> str:
    """"ip:port" as the controller sees this client: the source address the system picks
    for ``remote`` (no packet sent) and the bound port."""
    host = bind_host
    if host in ("0.0.0.0", ""):
        s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            s.connect(remote)  # UDP: chooses the route and source address, sends nothing
            host = s.getsockname()[0]
        except OSError:
            pass
        finally:
            s.close()
    return f"{host}:{local_port}"


# ----- the state file --------------------------------------------------------------------------

def state_dir() -> Path:
    """Where the controllers' state files live (module doc)."""
    env = os.environ.get("PLANECAL_STATE_DIR")
    if env:
        return Path(env)
    xdg = os.environ.get("XDG_STATE_HOME")
    return (Path(xdg) if xdg else Path.home() / ".local" / "state") / "planecal"


def default_state_path(remote: tuple[str, int]) -> Path:
    """The state file of the controller at ``remote`` (ip, port)."""
    return state_dir() / f"fd11-{remote[0]}-{remote[1]}.state"


def is_state_file(path: str | Path) -> bool:
    """Whether ``path`` holds an FD11 state line (what the output guard lets a run
    rewrite)."""
    try:
        with open(path, "rb") as f:
            head = f.read(len(STATE_TAG))
    except OSError:
        return False
    return head in (STATE_TAG, OLD_TAG[:len(STATE_TAG)])


def _line(delta, reference, sent_ms: int, client: str) -> bytes:
    refs = (b" -" * N_JOINTS if reference is None
            else b"".join(b" %010d" % (int(v) & 0xFFFFFFFF) for v in reference))
    body = (STATE_TAG + b"".join(b" %+011d" % int(v) for v in delta) + refs
            + b" %013d %s" % (sent_ms, client.encode("ascii", "replace")))
    return body + b" crc32=%08x\n" % zlib.crc32(body)


def _parse(path: Path, data: bytes) -> LastSession:
    bad = InputError(f"{path}: line 1: not an FD11 state line ({STATE_TAG.decode()}: 6 deltas, "
                     f"6 reference counts, time, client, crc32)")
    # line 1 only: a kill between writing a shorter line and truncating the file leaves
    # the end of the longer one after it
    line = data.split(b"\n", 1)[0]
    if b"\n" not in data or b" crc32=" not in line:
        raise bad
    body, crc = line.rsplit(b" crc32=", 1)
    fields = body.split(b" ")
    try:
        if fields[0] == OLD_TAG and len(fields) == 7:
            delta = np.array([int(v) for v in fields[1:7]], np.int64)
            ref = sent_at = client = None
        elif fields[0] == STATE_TAG and len(fields) == 15:
            delta = np.array([int(v) for v in fields[1:7]], np.int64)
            ref = (None if fields[7:13] == [b"-"] * N_JOINTS
                   else np.array([int(v) for v in fields[7:13]], np.int64))
            sent_at, client = int(fields[13]) / 1000.0, fields[14].decode("ascii")
            client = None if client == "-" else client
        else:
            raise bad
        ok = int(crc, 16) == zlib.crc32(body) and len(crc) == 8
    except (ValueError, UnicodeDecodeError):
        raise bad from None
    if not ok or np.any(np.abs(delta) > INT32_MAX):
        raise InputError(f"{path}: line 1: FD11 state line damaged (checksum or fields)")
    return LastSession(path, delta, ref, sent_at, client)


class StateFile:
    """The state file of one controller (module doc). `read` gives the last session; the
    link calls `sending` just before each packet and `answered` after each reply taken.
    The file (and its directory) is created at the first `sending`, not before: a run that
    fails before sending anything leaves nothing. Each write is one ``pwrite`` of the whole
    line at offset 0, no fsync: a killed planecal leaves it current (a PC power loss may
    leave it seconds old; the checksum catches a torn line)."""

    def __init__(self, path: str | Path):
        self.path = Path(path)
        self._fd: int | None = None
        self._size = 0
        self._last = self.read(self.path)
        self.delta = (np.zeros(N_JOINTS, np.int64) if self._last is None
                      else self._last.delta.copy())
        self.reference = None if self._last is None else self._last.reference
        self.client = None if self._last is None else self._last.client
        self._sent_ms = 0

    @property
    def last(self) -> LastSession | None:
        """The session recorded when this file was opened (None: none)."""
        return self._last

    @staticmethod
    def read(path: str | Path) -> LastSession | None:
        """The recorded session; None when the file does not exist; `InputError` (file and
        problem in one line) when it is not an intact record."""
        path = Path(path)
        try:
            with open(path, "rb") as f:
                data = f.read(MAX_STATE_BYTES + 1)
        except FileNotFoundError:
            return None
        except OSError as e:
            raise InputError(f"{path}: cannot read the FD11 state file ({e.strerror})") from None
        if len(data) > MAX_STATE_BYTES:
            raise InputError(f"{path}: line 1: not an FD11 state line (over {MAX_STATE_BYTES} "
                             f"bytes)")
        return _parse(path, data)

    def sending(self, delta: np.ndarray | None = None) -> None:
        """Record that a packet is about to go out, now, and with ``delta`` the delta it
        carries (given once the controller has answered this session: a packet within the
        step limit of an answered one, which the controller takes if it arrives -- so a
        run interrupted while it waits for the reply records what the controller most
        likely holds, and the other candidate is one step away). A session's first packet
        is recorded only when answered (a wrong one trips the controller, which then
        holds the delta before it)."""
        self._sent_ms = int(time.time() * 1000)
        if delta is not None:
            self.delta = np.asarray(delta, np.int64).copy()
        self._write()

    def answered(self, delta: np.ndarray, reference: np.ndarray, client: str) -> None:
        """Record the delta the controller answered, its reference and the client."""
        self.delta = np.asarray(delta, np.int64).copy()
        self.reference = np.asarray(reference, np.int64).copy()
        self.client = client
        self._write()

    def _write(self) -> None:
        line = _line(self.delta, self.reference, self._sent_ms, self.client or "-")
        try:
            if self._fd is None:
                self.path.parent.mkdir(parents=True, exist_ok=True)
                self._fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
            os.pwrite(self._fd, line, 0)
            if len(line) != self._size:
                os.ftruncate(self._fd, len(line))
                self._size = len(line)
        except OSError as e:
            raise LinkError(f"{self.path}: cannot record the FD11 state ({e.strerror}); "
                            f"nothing sent") from None

    def close(self) -> None:
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None
