# slapse in a container, in two stages (docs/DEPLOY.md):
#   build    Debian 12 + the toolchain and -dev packages (deploy/install-deps.sh --build);
#            builds the one `slapse` binary, Release, stripped
#   runtime  Debian 12 + only the shared libraries that binary loads (taken from the
#            packages of deploy/install-deps.sh --runtime in a stage between);
#            runs as the non-root user `slapse`
#
#   podman build --format docker -t slapse .      # --format docker keeps the HEALTHCHECK
#   podman run --rm -d -p 50051:50051 -p 8080:8080 -v slapse-data:/var/lib/slapse slapse
#   podman run --rm -v "$PWD/out:/out" slapse simulate --out /out/drive
#
# Ports: 50051 gRPC (slapse.v1.SlapseService, grpc.health.v1.Health, reflection),
# 8080 HTTP (/metrics, dashboard), 8554 RTSP ingest, 40000-40099/udp RTP.
# Data: /var/lib/slapse (the SQLite session store).

FROM debian:12 AS build
WORKDIR /src
COPY deploy/install-deps.sh deploy/install-deps.sh
RUN bash deploy/install-deps.sh --build && rm -rf /var/lib/apt/lists/*
COPY . .
# The ccache directory is a build cache mount: a rebuild after a source change
# recompiles only what changed.
RUN --mount=type=cache,target=/ccache \
    CCACHE_DIR=/ccache CCACHE_BASEDIR=/src \
    cmake -S . -B /build -G Ninja -DCMAKE_BUILD_TYPE=Release -DSLAPSE_BUILD_TESTS=OFF \
      -DCMAKE_CXX_COMPILER_LAUNCHER=ccache \
 && CCACHE_DIR=/ccache CCACHE_BASEDIR=/src cmake --build /build --target slapse -j "$(nproc)" \
 && strip -o /slapse /build/client/cli/slapse

# The runtime packages (deploy/install-deps.sh --runtime), installed here only to
# take from them the shared libraries slapse loads: its ldd closure, minus what
# the base image already has. Their Debian dependencies that slapse never loads
# (Mesa's GL drivers and LLVM, GDAL's and PROJ's data, docs) stay behind.
FROM debian:12 AS runtime-libs
RUN find / -xdev \( -type f -o -type l \) -path '*/lib*' | sed 's#^/lib/#/usr/lib/#' | sort -u > /tmp/base-files
COPY deploy/install-deps.sh /tmp/install-deps.sh
RUN bash /tmp/install-deps.sh --runtime && rm -rf /var/lib/apt/lists/*
COPY --from=build /slapse /usr/local/bin/slapse
# The RTSP push ingest's GStreamer plugins (dlopen'ed, so not in slapse's ldd; the
# record pipeline of server/rtsp_ingest.cc) and the plugin scanner come along by name,
# with their own ldd closures.
RUN set -e; mkdir /closure; gst="$(ls -d /usr/lib/*/gstreamer-1.0)"; \
    extra="$(ls /usr/lib/*/gstreamer1.0/gstreamer-1.0/gst-plugin-scanner)"; \
    for p in coreelements playback typefindfunctions app rtp rtpmanager udp mpegtsmux \
             videoparsersbad; do extra="$extra $gst/libgst$p.so"; done; \
    for lib in $extra $(ldd /usr/local/bin/slapse $extra | awk '/=> \// {print $3}' | sort -u); do \
      dest="$(readlink -f "$(dirname "$lib")")/$(basename "$lib")"; \
      grep -qxF "$dest" /tmp/base-files && continue; \
      mkdir -p "/closure$(dirname "$dest")"; cp -L "$lib" "/closure$dest"; \
    done; \
    echo "runtime-libs: $(find /closure -type f | wc -l) libraries, $(du -sh /closure | cut -f1)"

FROM debian:12 AS runtime
COPY --from=runtime-libs /closure/ /
COPY --from=build /slapse /usr/local/bin/slapse
# Every library slapse needs must resolve, or the build fails here.
RUN ldconfig && ! ldd /usr/local/bin/slapse | grep "not found" \
 && useradd --system --uid 10001 --user-group --home-dir /var/lib/slapse --shell /usr/sbin/nologin slapse \
 && mkdir -p /var/lib/slapse && chown slapse:slapse /var/lib/slapse
USER slapse
WORKDIR /var/lib/slapse
VOLUME /var/lib/slapse
# gRPC, HTTP (/metrics, dashboard), RTSP ingest of every push session, and the UDP
# range RTP arrives on (RTP/SDP sessions, RTSP publishers over UDP; docs/DEPLOY.md)
EXPOSE 50051 8080 8554 40000-40099/udp
# Healthy = the gRPC health service answers SERVING for slapse.v1.SlapseService.
HEALTHCHECK --interval=10s --timeout=3s --start-period=5s --retries=3 \
  CMD ["slapse", "health", "--server", "127.0.0.1:50051", "--service", "slapse.v1.SlapseService"]
ENTRYPOINT ["slapse"]
# A container must listen on 0.0.0.0. Without TLS and tokens that needs --insecure
# (anyone who reaches the port has every session): for a secure setup mount the
# certificates and a tokens file and replace --insecure with --tls-cert/--tls-key/
# --tokens-file (README "Secure setup").
CMD ["serve", "--address", "0.0.0.0", "--insecure", "--port", "50051", "--http-port", "8080", \
     "--rtsp-port", "8554", "--rtp-ports", "40000-40099", "--data-dir", "/var/lib/slapse"]
