# Debian's Prometheus, configured by deploy/compose/prometheus.yml (mounted).
FROM debian:12
COPY deploy/install-deps.sh /tmp/install-deps.sh
RUN bash /tmp/install-deps.sh --prometheus && rm -rf /var/lib/apt/lists/* /tmp/install-deps.sh
USER prometheus
EXPOSE 9090
ENTRYPOINT ["prometheus", "--config.file=/etc/slapse/prometheus.yml", \
            "--storage.tsdb.path=/tmp/prometheus", "--web.listen-address=0.0.0.0:9090"]
