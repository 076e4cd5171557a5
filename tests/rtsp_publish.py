#!/usr/bin/python3
"""A camera that publishes an MPEG-TS file (MPEG-2 video) over RTSP with
GStreamer's rtspclientsink (ANNOUNCE / SETUP / RECORD, RTP over TCP, TEARDOWN
at the end), at real time. The second publisher implementation of the RTSP
push tests (ffmpeg is the first).

    rtsp_publish.py FILE rtsp://USER:PASSWORD@HOST:PORT/PATH

Exit status 0 once the whole file was sent and the server answered the
TEARDOWN, 1 on an error (e.g. 401 from the server).

Needs python3-gi, GStreamer's base, good and bad plugins and gstreamer1.0-rtsp
(deploy/install-deps.sh).
"""
import sys
from urllib.parse import urlsplit, unquote

import gi

gi.require_version("Gst", "1.0")
from gi.repository import Gst  # noqa: E402


def teardown(pipeline, bus):
    """Sends TEARDOWN and waits for the server's answer; True if it came.

    rtspclientsink (1.22) sends TEARDOWN from its own thread, queued on
    PAUSED -> READY, and its READY -> NULL cancels that request when the
    thread has not taken it up yet: the connection is then closed without a
    TEARDOWN. Setting NULL at once (as this script did) lost that race under
    CPU load, and the server rightly reported a lost camera. So: READY
    first, then wait until the "close" request has ended.
    """
    pipeline.set_state(Gst.State.READY)
    while True:
        msg = bus.timed_pop_filtered(
            10 * Gst.SECOND, Gst.MessageType.PROGRESS | Gst.MessageType.ERROR)
        if msg is None:
            print("rtsp_publish: TEARDOWN not answered within 10 s", file=sys.stderr)
            return False
        if msg.type == Gst.MessageType.ERROR:
            # Leaving PLAYING interrupts the connection's I/O, which can fail
            # an RTCP packet being written at that moment; the TEARDOWN is
            # sent after that and its own outcome decides.
            err, _ = msg.parse_error()
            print("rtsp_publish: while stopping: %s" % err.message, file=sys.stderr)
            continue
        kind, code, text = msg.parse_progress()
        if code != "close" or kind in (Gst.ProgressType.START, Gst.ProgressType.CONTINUE):
            continue
        if kind != Gst.ProgressType.COMPLETE:
            print("rtsp_publish: TEARDOWN failed: %s" % text, file=sys.stderr)
        return kind == Gst.ProgressType.COMPLETE


def main():
    if len(sys.argv) != 3:
        print(__doc__, file=sys.stderr)
        return 2
    path, url = sys.argv[1], sys.argv[2]
    Gst.init(None)
    parts = urlsplit(url)
    location = "rtsp://%s:%d%s" % (parts.hostname, parts.port, parts.path)
    pipeline = Gst.parse_launch(
        "filesrc name=src ! tsdemux ! mpegvideoparse ! "
        "rtspclientsink name=sink protocols=tcp latency=0")
    pipeline.get_by_name("src").set_property("location", path)
    sink = pipeline.get_by_name("sink")
    sink.set_property("location", location)
    if parts.username:
        sink.set_property("user-id", unquote(parts.username))
        sink.set_property("user-pw", unquote(parts.password or ""))
    pipeline.set_state(Gst.State.PLAYING)
    bus = pipeline.get_bus()
    msg = bus.timed_pop_filtered(60 * Gst.SECOND, Gst.MessageType.EOS | Gst.MessageType.ERROR)
    ok = msg is not None and msg.type == Gst.MessageType.EOS
    if msg is not None and msg.type == Gst.MessageType.ERROR:
        err, _ = msg.parse_error()
        print("rtsp_publish: %s" % err.message, file=sys.stderr)
    if ok:
        ok = teardown(pipeline, bus)
    pipeline.set_state(Gst.State.NULL)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
