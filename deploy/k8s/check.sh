#!/usr/bin/env bash
# Checks deploy/k8s without a cluster (there is none on the development
# machines): renders it with `kubectl kustomize`, then
#   1. cross-checks the rendered objects (python3-yaml): selectors match pod
#      labels, the StatefulSet's serviceName is a headless Service, every
#      targetPort names a container port, volumes and the generated ConfigMap
#      exist, $(VARS) in args are defined, --peers names exactly the
#      StatefulSet's pods (slapse-N.<serviceName>:50051), --replica-id is the
#      pod name from the downward API;
#   2. checks that haproxy.cfg is deploy/k8s/haproxy-cfg.sh's output for those
#      replicas (full DNS names in the objects' namespace, "default" unless
#      kustomization.yaml sets one: HAProxy's resolver does not use search
#      domains) and that HAProxy accepts it (`haproxy -c`);
#   3. tries `kubectl apply --dry-run=client`, which needs an API server for
#      discovery: without one it says so (not counted as a pass; pass
#      --require-api to make it an error).
# Needs kubectl (>= 1.24: kustomize built in), python3-yaml and haproxy.
#   bash deploy/k8s/check.sh [--require-api]
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
require_api=0
[[ "${1:-}" == "--require-api" ]] && require_api=1
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT

command -v kubectl >/dev/null || { echo "check: kubectl not found" >&2; exit 1; }
command -v haproxy >/dev/null || { echo "check: haproxy not found (install-deps.sh --haproxy)" >&2; exit 1; }
echo "check: $(kubectl version --client 2>/dev/null | head -2 | tr '\n' ' ')"
kubectl kustomize "$here" > "$tmp/rendered.yaml"
# The optional per-replica RTSP Services (rtsp-external.yaml, not in the
# kustomization by default) are checked with the rest.
if ! grep -q "rtsp-external.yaml" "$here/kustomization.yaml"; then
  { echo "---"; cat "$here/rtsp-external.yaml"; } >> "$tmp/rendered.yaml"
fi
echo "check: kubectl kustomize rendered $(grep -c '^kind:' "$tmp/rendered.yaml") objects"

# 1. Cross-references; prints the replica list for step 2.
python3 - "$tmp/rendered.yaml" > "$tmp/replicas" <<'PY'
import re, sys, yaml
docs = [d for d in yaml.safe_load_all(open(sys.argv[1])) if d]
errors = []
def err(m): errors.append(m)
by_kind = {}
for d in docs:
    for f in ("apiVersion", "kind", "metadata"):
        if f not in d: err(f"an object without {f}")
    by_kind.setdefault(d["kind"], {})[d["metadata"]["name"]] = d
workloads = {**by_kind.get("StatefulSet", {}), **by_kind.get("Deployment", {})}
def matches(selector, labels):
    return all(labels.get(k) == v for k, v in selector.items())
for name, w in workloads.items():
    spec = w["spec"]; pod = spec["template"]
    labels = pod["metadata"].get("labels", {})
    if not matches(spec["selector"]["matchLabels"], labels):
        err(f"{name}: selector does not match the pod labels")
    volumes = {v["name"] for v in pod["spec"].get("volumes", [])}
    volumes |= {c["metadata"]["name"] for c in spec.get("volumeClaimTemplates", [])}
    for v in pod["spec"].get("volumes", []):
        cm = v.get("configMap", {}).get("name")
        if cm and cm not in by_kind.get("ConfigMap", {}):
            err(f"{name}: volume {v['name']} names ConfigMap {cm}, which is not rendered")
    for c in pod["spec"]["containers"]:
        for m in c.get("volumeMounts", []):
            if m["name"] not in volumes: err(f"{name}/{c['name']}: mount of unknown volume {m['name']}")
        env = {e["name"] for e in c.get("env", [])}
        for a in c.get("args", []):
            for var in re.findall(r"\$\((\w+)\)", a):
                if var not in env: err(f"{name}/{c['name']}: arg {a} uses undefined $({var})")
        for p in ("readinessProbe", "livenessProbe"):
            probe = c.get(p)
            if probe is None: err(f"{name}/{c['name']}: no {p}")
def pod_labels(w, i):
    # A StatefulSet's pod i also carries the controller's pod-name label.
    labels = dict(w["spec"]["template"]["metadata"]["labels"])
    if w["kind"] == "StatefulSet":
        labels["statefulset.kubernetes.io/pod-name"] = f'{w["metadata"]["name"]}-{i}'
    return labels
for name, s in by_kind.get("Service", {}).items():
    sel = s["spec"].get("selector", {})
    pods = [w for w in workloads.values()
            if any(matches(sel, pod_labels(w, i)) for i in range(w["spec"].get("replicas", 1)))]
    if not pods: err(f"Service {name}: selects no pods")
    for port in s["spec"]["ports"]:
        tp = port.get("targetPort")
        if isinstance(tp, str) and not any(
            tp == cp.get("name") for w in pods
            for c in w["spec"]["template"]["spec"]["containers"] for cp in c.get("ports", [])):
            err(f"Service {name}: targetPort {tp} is no container port of its pods")
replicas = []
for name, ss in by_kind.get("StatefulSet", {}).items():
    svc = by_kind.get("Service", {}).get(ss["spec"]["serviceName"])
    if svc is None or svc["spec"].get("clusterIP") != "None":
        err(f"StatefulSet {name}: serviceName {ss['spec']['serviceName']} is no headless Service")
        continue
    n = ss["spec"]["replicas"]
    c = ss["spec"]["template"]["spec"]["containers"][0]
    args = dict(a[2:].split("=", 1) for a in c["args"] if a.startswith("--") and "=" in a)
    want = [f"{name}-{i}.{ss['spec']['serviceName']}:50051" for i in range(n)]
    if args.get("peers", "").split(",") != want:
        err(f"StatefulSet {name}: --peers is {args.get('peers')}, want {','.join(want)}")
    pod_name = [e for e in c.get("env", []) if e.get("valueFrom", {}).get("fieldRef", {}).get("fieldPath") == "metadata.name"]
    if not pod_name or args.get("replica-id") != f"$({pod_name[0]['name']})":
        err(f"StatefulSet {name}: --replica-id is not the pod name (downward API metadata.name)")
    # HAProxy's resolver ignores resolv.conf's search domains: full names.
    ns = ss["metadata"].get("namespace", "default")
    replicas += [f"{name}-{i}={name}-{i}.{ss['spec']['serviceName']}.{ns}.svc.cluster.local:50051"
                 for i in range(n)]
if errors:
    print("\n".join("check: " + e for e in errors), file=sys.stderr); sys.exit(1)
print(" ".join(replicas))
PY
echo "check: cross-references ok (replicas: $(cat "$tmp/replicas"))"

# 2. The proxy's configuration is the generator's, and HAProxy takes it.
# shellcheck disable=SC2046
bash "$here/haproxy-cfg.sh" --dns --log $(cat "$tmp/replicas") > "$tmp/haproxy.cfg"
if ! diff -u "$here/haproxy.cfg" "$tmp/haproxy.cfg"; then
  echo "check: deploy/k8s/haproxy.cfg is stale; regenerate it:" >&2
  echo "  bash deploy/k8s/haproxy-cfg.sh --dns --log $(cat "$tmp/replicas") > deploy/k8s/haproxy.cfg" >&2
  exit 1
fi
haproxy -c -q -f "$here/haproxy.cfg"
echo "check: haproxy.cfg is haproxy-cfg.sh's output; haproxy -c accepts it"

# 3. Client-side dry run (needs an API server for discovery).
if kubectl apply --dry-run=client -f "$tmp/rendered.yaml" > "$tmp/dry-run.txt" 2>&1; then
  echo "check: kubectl apply --dry-run=client:"; sed 's/^/  /' "$tmp/dry-run.txt"
elif grep -q "connection refused\|failed to download openapi\|unable to recognize" "$tmp/dry-run.txt"; then
  echo "check: kubectl apply --dry-run=client NOT RUN: it needs an API server for discovery and none is reachable"
  ((require_api)) && exit 1
else
  cat "$tmp/dry-run.txt" >&2
  exit 1
fi
echo "check: PASS"
