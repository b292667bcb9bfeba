#!/usr/bin/env bash
# Container smoke test: build the Dockerfile without a Docker engine and run the image as it is
# deployed, then call it through its published port on 127.0.0.1.
#
#   bash deploy/container-smoke-test.sh          (as root; CI runs it from .ci/run)
#
# * base: the Dockerfile's base image cannot be pulled here, so a stand-in with the same
#   Python (Debian bookworm's python3 3.11, built by mmdebstrap) is tagged with its name;
# * build: buildah, no daemon, --pull=never (the stand-in is used), the host's CA bundle
#   mounted so that pip reaches the package index through an intercepting proxy;
# * run: podman with runc, read-only root filesystem, a tmpfs /tmp, the image's non-root
#   user, a memory limit, no capabilities, two workers, API keys from the environment;
# * checks: /healthz, /readyz, the image's HEALTHCHECK, a flatten of a bundled sample,
#   refusals of requests without a valid key, a request id, metrics summed over both workers,
#   JSON logs, writes refused outside /tmp, and a clean exit on SIGTERM.
set -euo pipefail
cd "$(dirname "$0")/.."

IMAGE=${SMOKE_IMAGE:-localhost/meshflat:smoke}
PORT=${SMOKE_PORT:-18080}
MEMORY=${SMOKE_MEMORY:-3g}
NAME=meshflat-smoke-$$
KEY=smoke-$(od -An -N12 -tx1 /dev/urandom | tr -d ' \n')
BASE=$(sed -n 's/^ARG PYTHON_IMAGE=//p' Dockerfile)
podman=(podman --storage-driver vfs)
run_options=(--runtime runc --ulimit nofile=1024:1024 --ulimit nproc=1000:1000)
work=$(mktemp -d)
# The image is removed at the end (vfs storage keeps full copies); the base stays, as a cache.
trap '"${podman[@]}" rm -f "$NAME" >/dev/null 2>&1 || true
      [ -n "${SMOKE_KEEP_IMAGE:-}" ] || "${podman[@]}" rmi -f "$IMAGE" >/dev/null 2>&1 || true
      rm -rf "$work"' EXIT

step() { printf '\n== %s\n' "$*"; }
fail() { printf 'FAILED: %s\n' "$*" >&2; "${podman[@]}" logs "$NAME" 2>&1 | tail -20 >&2 || true; exit 1; }

need=()
for tool in mmdebstrap buildah podman runc curl python3; do
  command -v "$tool" >/dev/null 2>&1 || need+=("$tool")
done
if [ ${#need[@]} -gt 0 ]; then
  step "installing ${need[*]}"
  apt-get update -qq
  DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${need[@]}" >/dev/null
fi

step "base image $BASE"
if "${podman[@]}" image exists "$BASE"; then
  echo "present"
else
  mmdebstrap --quiet --variant=minbase --include=python3,python3-venv,ca-certificates \
    bookworm "$work/rootfs.tar"
  "${podman[@]}" import --quiet "$work/rootfs.tar" "$BASE" >/dev/null
  echo "stand-in built with mmdebstrap and tagged $BASE"
fi

step "build $IMAGE"
started=$(date +%s)
buildah --storage-driver vfs bud --quiet --pull=never --isolation chroot --format docker \
  -v /etc/ssl/certs/ca-certificates.crt:/etc/ssl/certs/ca-certificates.crt:ro \
  -t "$IMAGE" . >/dev/null
size=$("${podman[@]}" image inspect --format '{{.Size}}' "$IMAGE")
base_size=$("${podman[@]}" image inspect --format '{{.Size}}' "$BASE")
user=$("${podman[@]}" image inspect --format '{{.Config.User}}' "$IMAGE")
echo "built in $(($(date +%s) - started)) s: $((size / 1000000)) MB" \
  "($(((size - base_size) / 1000000)) MB above the base); user $user"

step "run: read-only, non-root, memory $MEMORY, two workers, API keys"
"${podman[@]}" run -d --name "$NAME" "${run_options[@]}" \
  --read-only --tmpfs /tmp:rw,size=64m,mode=1777 --memory "$MEMORY" --memory-swap "$MEMORY" \
  --cap-drop ALL --security-opt no-new-privileges \
  -e MESHFLAT_API_KEYS="other-key,$KEY" -e MESHFLAT_WORKERS=2 \
  -p "127.0.0.1:$PORT:8000" "$IMAGE" >/dev/null
url=http://127.0.0.1:$PORT
for _ in $(seq 60); do
  curl -fs "$url/readyz" >/dev/null 2>&1 && break
  sleep 1
done
curl -fs "$url/readyz" >/dev/null || fail "/readyz did not answer 200 within 60 s"
uid=$("${podman[@]}" exec "$NAME" id -u)
[ "$uid" != 0 ] || fail "the service runs as root"
limit=$("${podman[@]}" exec "$NAME" sh -c \
  'cat /sys/fs/cgroup/memory.max 2>/dev/null || cat /sys/fs/cgroup/memory/memory.limit_in_bytes')
"${podman[@]}" exec "$NAME" sh -c 'touch /opt/meshflat/x' 2>/dev/null && fail "the root filesystem is writable"
echo "uid $uid; memory limit seen in the container: $limit bytes; / is read-only"

# Each check: what was asked, the status, and what must hold.
check() { # name, expected status, curl arguments...
  local name=$1 expected=$2
  shift 2
  local status
  status=$(curl -s -o "$work/body" -D "$work/headers" -w '%{http_code}' "$@")
  [ "$status" = "$expected" ] || fail "$name: status $status, expected $expected: $(head -c 300 "$work/body")"
  printf '%-44s %s\n' "$name" "$status"
}

step "requests to $url"
check "GET /healthz" 200 "$url/healthz"
check "GET /v1/samples without a key" 401 "$url/v1/samples"
grep -qi '^content-type: application/problem+json' "$work/headers" || fail "401 is not problem+json"
check "GET /v1/samples with a wrong key" 401 -H "X-API-Key: not-$KEY" "$url/v1/samples"
check "GET /v1/samples/fsaverage-head.ply (X-API-Key)" 200 -H "X-API-Key: $KEY" \
  "$url/v1/samples/fsaverage-head.ply"
cp "$work/body" "$work/head.ply"
params='{"center": "bbox_center", "rotation": {"pole": [0, 0, -1], "up": [0, 1, 0]},
         "region": {"cone": {"axis": [0, 0, 1], "half_angle_deg": 70}}}'
check "POST /v1/flatten (Bearer), scalp of the sample" 200 -H "Authorization: Bearer $KEY" \
  -H "X-Request-ID: smoke-flatten-1" -F "mesh=@$work/head.ply" -F "params=$params" \
  "$url/v1/flatten"
grep -qi '^x-request-id: smoke-flatten-1' "$work/headers" || fail "X-Request-ID not returned"
python3 - "$work/body" <<'EOF' || fail "the flatten answer"
import json, sys
answer = json.load(open(sys.argv[1]))
v = answer["validation"]
assert v["seam_free"] and v["star_shaped"], v
print(f"  {len(answer['faces']['ids']):,} triangles, {len(answer['vertices']['ids']):,} vertices,"
      f" seam-free, star-shaped, margin to the seam {v['margin_deg']['seam']:.1f} deg")
EOF
check "POST /v1/flatten without a key" 401 -F "mesh=@$work/head.ply" "$url/v1/flatten"

# Both workers answer /metrics with the sum over both; ask a few times.
for _ in 1 2 3 4; do
  check "GET /metrics" 200 "$url/metrics" >/dev/null
  grep -q '^meshflat_requests_total{.*route="/v1/flatten".*status="200".*} 1.0' "$work/body" \
    || fail "/metrics does not count the flatten: $(grep flatten "$work/body" | head -3)"
done
echo "GET /metrics (4 times: counts summed over both workers)"
grep -E '^meshflat_(requests_total\{.*/v1/flatten|rejections_total|jobs_in_flight)' "$work/body" \
  | sed 's/^/  /'

step "HEALTHCHECK of the image"
"${podman[@]}" healthcheck run "$NAME" 2>/dev/null || fail "the image's health check failed"
echo "healthy"

step "stop with SIGTERM while a job is computing"
# podman says it cannot schedule the health check without systemd; `healthcheck run` above
# ran it directly. uvicorn's supervisor looks at its signals every half second and then asks
# each worker to stop, so the job must compute for well over that: 300,000 graft sites on the
# Nefertiti bust compute for about 3 s (an estimated 739 MiB: within a worker's budget in a
# container of 3g shared by two). A fit of a sample computes for less than 0.4 s, and once
# ended before the supervisor had seen SIGTERM.
check "GET /v1/samples/nefertiti-lowres.obj" 200 -H "X-API-Key: $KEY" \
  "$url/v1/samples/nefertiti-lowres.obj"
cp "$work/body" "$work/bust.obj"
# The container's first process, found before the job starts: `podman inspect` takes a good
# part of a second.
init_pid=$("${podman[@]}" inspect --format '{{.State.Pid}}' "$NAME")
curl -s -o "$work/sites" -w '%{http_code}' -H "X-API-Key: $KEY" -F "mesh=@$work/bust.obj" \
  -F 'params={"units": "mm", "density_per_cm2": 50, "count": 300000, "output": "ply"}' \
  "$url/v1/sites" > "$work/job-status" &
job=$!
computing=no
for _ in $(seq 300); do  # until the job is computing
  if curl -s "$url/metrics" | grep -q '^meshflat_jobs_computing 1.0'; then computing=yes; break; fi
  sleep 0.01
done
[ "$computing" = yes ] || fail "the job was not seen computing: $(cat "$work/job-status" 2>/dev/null)"
# SIGTERM goes straight to the container's first process: `podman stop` can take longer to
# deliver it than the job takes to finish, and then nothing would be in progress to drain.
started=$(date +%s%N)
kill -TERM "$init_pid"
timeout 30 "${podman[@]}" wait "$NAME" >/dev/null || fail "no exit within 30 s of SIGTERM"
wait "$job" || true
code=$("${podman[@]}" inspect --format '{{.State.ExitCode}}' "$NAME")
[ "$code" = 0 ] || fail "exit status $code after SIGTERM"
[ "$(cat "$work/job-status")" = 200 ] || fail "the job in progress got $(cat "$work/job-status")"
head -c 3 "$work/sites" | grep -q '^ply' || fail "the job's answer is not a PLY file"
echo "the job in progress was answered 200 ($(wc -c < "$work/sites") bytes of PLY);" \
  "exited 0 after $((($(date +%s%N) - started) / 1000000)) ms"
mkdir -p artifacts
"${podman[@]}" logs "$NAME" 2>&1 | grep "^{" > artifacts/container-smoke.log
limit_bytes=$("${podman[@]}" inspect --format '{{.HostConfig.Memory}}' "$NAME")
python3 - artifacts/container-smoke.log "$KEY" "$limit_bytes" <<'EOF' || fail "the logs"
import json, sys
lines = [line for line in open(sys.argv[1]) if line.startswith("{")]
entries = [json.loads(line) for line in lines]
text = open(sys.argv[1]).read()
assert sys.argv[2] not in text, "an API key in the log"
assert "ply" not in text.replace("fsaverage-head.ply", ""), "a file name in the log"
requests = [e for e in entries if e["message"] == "request"]
assert any(e["request_id"] == "smoke-flatten-1" and e["status"] == 200 for e in requests)
assert any(e["message"].startswith("Finished server process") for e in entries)
# Each worker's memory budget comes from the container's limit (service.settings).
budgets = [e["message"] for e in entries if e["message"].startswith("memory budget")]
limit = int(sys.argv[3]) // 2**20
assert len(budgets) >= 2 and all(f"container limit of {limit} MiB" in b for b in budgets), budgets
# The job was answered after the server had received SIGTERM: a graceful stop.
sigterm = next(e["time"] for e in entries if e["message"].startswith("Received SIGTERM"))
job = next(e for e in requests if e["route"] == "/v1/sites")
assert job["status"] == 200 and job["time"] > sigterm, (job, sigterm)
# The kernels compiled into the image are loaded, not compiled again at start (each worker's
# self-check says how long they took; compiling them takes about 19 s).
checks = [e["message"] for e in entries if e["message"].startswith("self-check")]
kernels = [float(m.rsplit("compiled kernels ready in ", 1)[1].split()[0]) for m in checks]
assert kernels and max(kernels) < 5.0, checks
print(f"  compiled kernels loaded from the image in {max(kernels):.1f} s at most;")
print(f"  {len(entries)} JSON log lines, {len(requests)} request lines, no key, no upload name;")
for e in requests[-3:]:
    print("  ", json.dumps(e))
EOF

printf '\nsmoke test passed: image %s, %d MB\n' "$IMAGE" $((size / 1000000))
