#!/usr/bin/python3
"""A real RTSP server for the tests: GStreamer's gst-rtsp-server serving one
MPEG-TS file (MPEG-1/2 video) at rtsp://127.0.0.1:PORT/PATH.

Every client gets its own media (not shared), played from the file's start in
real time over RTP (UDP or TCP interleaved, as the client asks). At the file's
end the RTP session sends RTCP BYE. The script prints one line
"READY rtsp://127.0.0.1:PORT/PATH" on stdout once it listens, then runs until
killed.

  rtsp_server.py FILE [--port N] [--path NAME]

--port 0 (the default) lets the kernel pick a free port; pass a fixed port to
restart a server at the same URL.
Needs python3-gi, gir1.2-gst-rtsp-server-1.0 and GStreamer's base, good and
bad plugins (deploy/install-deps.sh).
"""
import argparse
import os
import sys

import gi

gi.require_version("Gst", "1.0")
gi.require_version("GstRtspServer", "1.0")
from gi.repository import GLib, Gst, GstRtspServer  # noqa: E402


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("file", help="an MPEG-TS file with MPEG-1/2 video")
    parser.add_argument("--port", type=int, default=0, help="TCP port (0: a free one)")
    parser.add_argument("--path", default="stream", help="the URL's path")
    args = parser.parse_args()
    if not os.path.isfile(args.file):
        sys.exit("rtsp_server.py: no file " + args.file)

    Gst.init(None)
    # tsdemux finds the video; mpegvideoparse frames it; rtpmpvpay (RFC 2250,
    # static payload type 32) is what FFmpeg's RTSP client depacketises.
    source = 'filesrc location="{}"'.format(args.file.replace('"', '\\"'))
    launch = "( {} ! tsdemux ! mpegvideoparse ! rtpmpvpay name=pay0 pt=32 )".format(source)

    factory = GstRtspServer.RTSPMediaFactory()
    factory.set_launch(launch)
    factory.set_shared(False)
    server = GstRtspServer.RTSPServer()
    server.set_address("127.0.0.1")
    server.set_service(str(args.port))
    server.get_mount_points().add_factory("/" + args.path, factory)
    if server.attach(None) == 0:
        sys.exit("rtsp_server.py: cannot listen on 127.0.0.1:{}".format(args.port))
    print("READY rtsp://127.0.0.1:{}/{}".format(server.get_bound_port(), args.path), flush=True)
    GLib.MainLoop().run()


if __name__ == "__main__":
    main()
