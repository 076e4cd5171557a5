# slapse in a container: the same install script as the README and CI.
#   docker build -t slapse .
#   docker run --rm -v "$PWD/out:/out" slapse simulate --out /out/drive
#   docker run --rm -p 50051:50051 slapse serve --port 50051 --insecure   # the gRPC service
#   (a container must listen on 0.0.0.0: --insecure, or TLS + tokens, README "Secure setup")
FROM debian:12
WORKDIR /src
COPY deploy/install-deps.sh deploy/install-deps.sh
RUN bash deploy/install-deps.sh && rm -rf /var/lib/apt/lists/*
COPY . .
RUN bash deploy/build.sh -DSLAPSE_BUILD_TESTS=OFF -DCMAKE_BUILD_TYPE=Release \
 && cmake --install build --prefix /usr/local \
 && rm -rf build
EXPOSE 50051
ENTRYPOINT ["slapse"]
CMD ["--help"]
