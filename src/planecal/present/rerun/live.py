"""A live view of a run (``rehearse --live``, ``sample --live``): the sampling recording's
own observer and blueprint (``present.rerun.sampling``), streamed to a viewer as the run
happens instead of (or besides) written to a file.

rerun-sdk 0.41 serves it from this process: a gRPC server sink (``rr.GrpcServerSink``,
bound to 127.0.0.1) keeps the stream in memory (``memory_limit``; the oldest data is
dropped first, never the static cell) for any viewer that connects, early or late, and
``rr.serve_web_viewer`` serves rerun's web viewer on ``web_port`` (its page is static
and, in 0.41, served on every interface; the data stays on 127.0.0.1). Both return at
once and run on rerun's own threads; logging into the stream never waits for a viewer.
With ``path`` a file sink records the same stream. The servers stop when the recording
is closed: a viewer keeps what it received.
"""
from __future__ import annotations

import urllib.parse
import uuid
from dataclasses import dataclass

from planecal.base.errors import InputError

GRPC_PORT = 9876
WEB_PORT = 9090


@dataclass(frozen=True)
class LiveOptions:
    """Where to serve: the gRPC port (127.0.0.1), the web viewer's port (0: none; connect
    a native viewer with ``rerun URL``) and the server's memory limit."""
    grpc_port: int = GRPC_PORT
    web_port: int = WEB_PORT
    memory_limit: str = "1GiB"


@dataclass(frozen=True)
class LiveView:
    grpc_url: str  # rerun+http://127.0.0.1:PORT/proxy (rerun URL, a native viewer)
    web_url: str | None  # the web viewer's page, connected to the stream

    def describe(self) -> str:
        web = f"open {self.web_url} (web viewer) or " if self.web_url else ""
        return f"live view: {web}run `rerun {self.grpc_url}` (native viewer)"


def open_live(blueprint, name: str, options: LiveOptions, path=None):
    """(recording stream, LiveView): the stream served live (module docstring), also
    written to ``path`` when given."""
    from planecal.present.rerun.common import APP_ID, _rr

    rr = _rr()
    rec = rr.RecordingStream(APP_ID, recording_id=str(uuid.uuid4()))
    rec.set_log_time_enabled(False)
    sinks = [rr.GrpcServerSink(bind_ip="127.0.0.1", port=options.grpc_port,
                               server_memory_limit=options.memory_limit)]
    if path is not None:
        sinks.append(rr.FileSink(str(path)))
    try:
        rec.set_sinks(*sinks, default_blueprint=blueprint)
    except Exception as e:  # rerun's own error types: a port taken, a path not writable
        raise InputError(f"--live-port {options.grpc_port}: cannot serve the live view "
                         f"({str(e).splitlines()[0] if str(e) else type(e).__name__})") from None
    url = f"rerun+http://127.0.0.1:{options.grpc_port}/proxy"
    web = None
    if options.web_port:
        try:
            rr.serve_web_viewer(web_port=options.web_port, open_browser=False, connect_to=url)
        except Exception as e:
            rec.disconnect()
            raise InputError(f"--live-web-port {options.web_port}: cannot serve the web "
                             f"viewer ({str(e).splitlines()[0] if str(e) else e!r})") from None
        web = f"http://localhost:{options.web_port}/?url={urllib.parse.quote(url, safe='')}"
    rec.send_recording_name(name)
    rec.log("/", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    return rec, LiveView(url, web)
