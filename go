#!/usr/bin/env bash
# One entry point that sets up everything on a fresh Debian 12 machine (as root) and runs facecast.
#   ./go demo        the main job on built-in defaults
#   ./go test        the whole test suite
#   ./go <args>      any other `facecast` subcommand, e.g. ./go bench core
# Set-up is idempotent: apt packages only when missing, the virtual environment only when
# pyproject.toml changed since the last install.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
cd "$here"
bash scripts/setup.sh >&2
# shellcheck disable=SC1091
source .venv/bin/activate
case "${1:-demo}" in
  test) shift; exec python -m pytest "$@" ;;
  *) exec facecast "$@" ;;
esac
