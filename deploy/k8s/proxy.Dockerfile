# The routing proxy's image: Debian 12's HAProxy 2.6 (install-deps.sh --haproxy),
# its configuration mounted at /etc/haproxy/haproxy.cfg (deploy/k8s/proxy.yaml).
#   docker build -t slapse-proxy -f deploy/k8s/proxy.Dockerfile deploy
FROM debian:12
COPY install-deps.sh /tmp/install-deps.sh
RUN bash /tmp/install-deps.sh --haproxy && rm -rf /var/lib/apt/lists/* /tmp/install-deps.sh
USER haproxy
EXPOSE 50051
ENTRYPOINT ["haproxy"]
CMD ["-db", "-W", "-f", "/etc/haproxy/haproxy.cfg"]
