# A simulated camera: the slapse image (for `simulate`, `create`, `watch`) plus
# ffmpeg, which publishes the drive over RTSP at real time (deploy/compose/camera.sh).
FROM localhost/slapse:latest
USER root
COPY deploy/install-deps.sh /tmp/install-deps.sh
RUN bash /tmp/install-deps.sh --camera && rm -rf /var/lib/apt/lists/* /tmp/install-deps.sh
COPY deploy/compose/camera.sh /usr/local/bin/camera.sh
USER slapse
# The camera is not a server: no health check from the slapse image.
HEALTHCHECK NONE
ENTRYPOINT ["bash", "/usr/local/bin/camera.sh"]
