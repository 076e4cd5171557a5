#!/bin/sh
# Installs tests/web/node_modules from package-lock.json (`npm ci`) unless an
# install from this lockfile has already completed. Safe to run concurrently:
# `npm ci` first deletes node_modules, so two at once break each other; the
# install runs under an exclusive lock and the others wait, then see it done.
# npm writes node_modules/.package-lock.json when an install completes, so a
# killed install (no such file, or older than the lockfile) is redone.
set -eu
web_dir=$(cd "$(dirname "$0")" && pwd)
exec 9>"$web_dir/.npm-ci.lock"
flock 9
done_marker="$web_dir/node_modules/.package-lock.json"
if [ -f "$done_marker" ] && [ ! "$web_dir/package-lock.json" -nt "$done_marker" ]; then
  exit 0
fi
npm ci --no-audit --no-fund --prefix "$web_dir"
