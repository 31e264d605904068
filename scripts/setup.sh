#!/usr/bin/env bash
# Idempotent machine and environment set-up for facecast (Debian 12, root). Called by ./go.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."

# System packages: espeak-ng and Festival with three voices (speech synthesis for corpora and
# the demo), ffmpeg (video I/O),
# PortAudio (microphone via sounddevice), PulseAudio (a virtual microphone in tests),
# Mesa EGL (headless moderngl rendering), Chromium (the browser viewer's test) and Xvfb (a
# display for the Python viewer's window test), redis-server (the server's cluster tests and
# `facecast bench capacity --cluster`).
apt_pkgs=(espeak-ng libespeak-ng1 festival festvox-kallpc16k festvox-kdlpc16k festvox-us-slt-hts ffmpeg
          libportaudio2 pulseaudio pulseaudio-utils libegl1 libegl-mesa0 libgl1-mesa-dri python3-venv
          chromium xvfb redis-server)
missing=()
for p in "${apt_pkgs[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "setup: installing ${missing[*]}"
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -qq
  apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi

if [ ! -x .venv/bin/python ]; then
  echo "setup: creating .venv"
  python3 -m venv .venv
fi
stamp=.venv/.facecast-installed
# Reinstall when the project metadata or the set of top-level packages changes (an editable
# install only maps the packages that existed when it was made).
# Every package at the exact version in constraints.txt (the versions CI last passed with): a new
# release on PyPI must not change what a fresh clone installs. `scripts/setup.sh --refresh-constraints`
# installs the newest versions pyproject.toml allows and writes them there (run the whole CI after).
want="$(cat pyproject.toml constraints.txt */__init__.py 2>/dev/null | sha256sum | cut -d' ' -f1)"
if [ "${1:-}" = "--refresh-constraints" ]; then
  echo "setup: installing the newest allowed Python packages and writing constraints.txt"
  .venv/bin/python -m pip install -q --upgrade pip
  .venv/bin/python -m pip install -q --upgrade --upgrade-strategy eager -e '.[dev]'
  { sed -n '/^#/p' constraints.txt; .venv/bin/python -m pip freeze --exclude-editable; } > constraints.txt.new
  mv constraints.txt.new constraints.txt
  want="$(cat pyproject.toml constraints.txt */__init__.py 2>/dev/null | sha256sum | cut -d' ' -f1)"
  echo "$want" > "$stamp"
elif [ ! -f "$stamp" ] || [ "$(cat "$stamp")" != "$want" ]; then
  echo "setup: installing Python packages (constraints.txt)"
  .venv/bin/python -m pip install -q --upgrade pip
  .venv/bin/python -m pip install -q -c constraints.txt -e '.[dev]'
  echo "$want" > "$stamp"
fi

# The per-frame numba kernels (realtime_core/*/compiled.py), compiled here once rather than by the
# first say/render/animate/serve (facecast warm-up: ~20 s of CPU, minutes of wall time on a busy
# machine). numba keys its cache by each source file's mtime and size (and numba's version, which
# the package stamp above covers), so this stamp is keyed the same way.
kstamp=realtime_core/__pycache__/facecast-kernels.stamp
kwant="$({ stat -c '%n %Y %s' realtime_core/*/compiled.py; cat "$stamp"; } | sha256sum | cut -d' ' -f1)"
if [ ! -f "$kstamp" ] || [ "$(cat "$kstamp")" != "$kwant" ]; then
  echo "setup: compiling the numba kernels (facecast warm-up; once per change of them)"
  .venv/bin/facecast warm-up
  mkdir -p realtime_core/__pycache__
  echo "$kwant" > "$kstamp"
fi

# npm packages (package.json at the root: three.js served to the browser viewer, playwright-core for
# its test): `npm ci` when the lock file changed since the last install.
# Node.js and npm: the machine image usually has them; a bare Debian gets its own packages (the browser
# viewer's tests, three.js, and glTF-Transform for compressed heads need them, so CI must not lack them).
if ! command -v npm >/dev/null; then
  echo "setup: installing nodejs npm"
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -qq
  apt-get install -y -qq --no-install-recommends nodejs npm >/dev/null
fi
if [ -f package-lock.json ]; then
  npm_want="$(cat package.json package-lock.json | sha256sum | cut -d' ' -f1)"
  if [ ! -f node_modules/.facecast-installed ] || [ "$(cat node_modules/.facecast-installed)" != "$npm_want" ]; then
    echo "setup: installing npm packages"
    npm ci --no-audit --no-fund --loglevel=error
    echo "$npm_want" > node_modules/.facecast-installed
  fi
fi
