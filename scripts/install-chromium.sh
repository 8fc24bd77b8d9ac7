#!/usr/bin/env bash
# Install a headless Chromium for the browser tests (report.html in headless Chromium; later the judge UI).
# Idempotent: does nothing when a Chromium/Chrome is already there ($PILWORLD_CHROMIUM, or chromium,
# chromium-browser, google-chrome, google-chrome-stable, chrome on PATH). Otherwise installs Debian's
# `chromium` package with apt-get when running as root or with password-less sudo.
#
# Without apt-get or root rights it only prints what to do and exits 0, so a bootstrap that calls it
# keeps going: the browser tests then skip with a reason. `--require` makes that case exit 1 instead.
# No browser is ever downloaded from anywhere but the system's package repositories (no Playwright).
set -euo pipefail

REQUIRE=0
for arg in "$@"; do
  case "$arg" in
    --require) REQUIRE=1 ;;
    -h|--help) sed -n '2,9p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    *) printf '[install-chromium] error: unknown argument %s (known: --require)\n' "$arg" >&2; exit 2 ;;
  esac
done

log() { printf '[install-chromium] %s\n' "$*" >&2; }

find_browser() {
  if [ -n "${PILWORLD_CHROMIUM:-}" ]; then
    command -v "$PILWORLD_CHROMIUM" 2>/dev/null && return 0
    [ -x "$PILWORLD_CHROMIUM" ] && { echo "$PILWORLD_CHROMIUM"; return 0; }
  fi
  for name in chromium chromium-browser google-chrome google-chrome-stable chrome; do
    command -v "$name" 2>/dev/null && return 0
  done
  return 1
}

give_up() {
  log "$1"
  log "install Chromium by hand (Debian/Ubuntu: apt-get install chromium; or set PILWORLD_CHROMIUM=/path/to/chrome);"
  log "until then the headless-browser tests (tests/pilworld/report/test_browser.py) are skipped"
  exit "$REQUIRE"
}

if found="$(find_browser)"; then
  # Debian's wrapper script prints a harmless shell warning on some machines; keep only the version line.
  log "found $found ($("$found" --version 2>/dev/null | grep -i -m1 -E 'chrom' || echo 'version unknown'))"
  exit 0
fi

command -v apt-get >/dev/null 2>&1 || give_up "no Chromium found and no apt-get on this machine"

if [ "$(id -u)" -eq 0 ]; then
  SUDO=()
elif command -v sudo >/dev/null 2>&1 && sudo -n true 2>/dev/null; then
  SUDO=(sudo -n)
else
  give_up "no Chromium found, and installing it needs root (run: sudo apt-get install chromium)"
fi

export DEBIAN_FRONTEND=noninteractive
log "installing Debian's chromium package with apt-get (about 100 MB of packages; fonts come with it)"
if ! "${SUDO[@]}" apt-get install -y -q chromium >/dev/null 2>&1; then
  # A fresh container has empty package lists: update them once and retry.
  "${SUDO[@]}" apt-get update -q >/dev/null || give_up "apt-get update failed"
  "${SUDO[@]}" apt-get install -y -q chromium >/dev/null || give_up "apt-get install chromium failed"
fi

found="$(find_browser)" || give_up "apt-get installed chromium but no chromium binary is on PATH"
log "installed $found ($("$found" --version 2>/dev/null | grep -i -m1 -E 'chrom' || echo 'version unknown'))"
