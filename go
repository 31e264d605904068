#!/usr/bin/env bash
# One entry point that sets up everything on a fresh Debian 12 machine (as root) and runs facecast.
#   ./go demo        the main job on built-in defaults
#   ./go test        the whole test suite
#   ./go <args>      any other `facecast` subcommand, e.g. ./go bench core
# Set-up is idempotent: apt packages only when missing, the virtual environment only when
# pyproject.toml changed since the last install.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
bash "$here/scripts/setup.sh" >&2
# shellcheck disable=SC1091
source "$here/.venv/bin/activate"
case "${1:-demo}" in
  # The tests run from the checkout (pytest's rootdir and configuration); a facecast command from
  # where it was called, so relative paths (-o out.mp4, a speech file) mean what the caller meant.
  # One worker per core, a whole test file per worker (module fixtures are built once); `-n 0` after it runs in one.
  test) shift; cd "$here"; exec python -m pytest -n auto --dist loadfile "$@" ;;
  *) exec facecast "$@" ;;
esac
