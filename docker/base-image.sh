#!/usr/bin/env bash
# Build the local base image where no image registry answers (FROM python:3.11-slim fails):
# Debian bookworm by debootstrap (python3 + venv), imported with `docker import`.
# Also fills docker/wheels/ with the project's dependency wheels (pip wheel on the host), which
# the Dockerfile installs offline. Reuses the image when its tag exists (FORCE=1 rebuilds).
# The last line printed is the image tag, for `BASE_IMAGE=$(docker/base-image.sh | tail -1)`.
set -euo pipefail
TAG="${BASE_TAG:-auv-swarm-base:bookworm}"
MIRROR="${DEBIAN_MIRROR:-http://deb.debian.org/debian}"
HERE="$(cd "$(dirname "$0")" && pwd)"
ROOT="$(dirname "$HERE")"

command -v docker >/dev/null || { echo "base-image.sh: docker is not installed" >&2; exit 2; }

# The wheelhouse: every runtime dependency of the project as a wheel for CPython 3.11 on Linux (this machine's
# architecture). pip download is incremental: present wheels are kept, new dependencies are added.
mkdir -p "$HERE/wheels"
PY="${PYTHON:-python3}"
mapfile -t DEPS < <("$PY" -c 'import sys, tomllib; print("\n".join(tomllib.load(open(sys.argv[1], "rb"))["project"]["dependencies"]))' "$ROOT/pyproject.toml")
echo "base-image.sh: dependency wheels into docker/wheels/" >&2
if ! "$PY" -m pip download -q --only-binary=:all: --python-version 3.11 --implementation cp \
    --platform "manylinux2014_$(uname -m)" --platform "manylinux_2_17_$(uname -m)" \
    --platform "manylinux_2_28_$(uname -m)" --platform "manylinux_2_31_$(uname -m)" \
    -d "$HERE/wheels" "${DEPS[@]}" "setuptools>=64" wheel >&2; then
    if [ -z "$(ls "$HERE"/wheels/*.whl 2>/dev/null)" ]; then
        echo "base-image.sh: pip download failed and docker/wheels/ is empty (is the package index reachable?)" >&2
        exit 1
    fi
    echo "base-image.sh: warning: pip download failed; building with the wheels already in docker/wheels/" >&2
fi

if docker image inspect "$TAG" >/dev/null 2>&1 && [ "${FORCE:-0}" != 1 ]; then
    echo "base-image.sh: reusing $TAG" >&2
    echo "$TAG"
    exit 0
fi
command -v debootstrap >/dev/null || {
    echo "base-image.sh: debootstrap is not installed (apt-get install debootstrap)" >&2
    exit 2
}
[ "$(id -u)" = 0 ] || { echo "base-image.sh: debootstrap needs root" >&2; exit 2; }

WORK="$(mktemp -d /tmp/auv-swarm-base.XXXXXX)"
trap 'rm -rf "$WORK"' EXIT
echo "base-image.sh: debootstrap bookworm into $WORK (about 100 s)" >&2
debootstrap --variant=minbase --include=python3,python3-venv,ca-certificates bookworm "$WORK/rootfs" "$MIRROR" >&2
rm -rf "$WORK"/rootfs/var/cache/apt/archives/*.deb "$WORK"/rootfs/var/lib/apt/lists/*
tar -C "$WORK/rootfs" -c . | docker import \
    --change 'ENV PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin' \
    --change 'ENV LANG=C.UTF-8' \
    --change 'CMD ["/bin/bash"]' - "$TAG" >&2
echo "$TAG"
