#!/usr/bin/env bash
# Fetches the Stanford bunny (Debian package glmark2-data) into heatsim's cache and checks its
# SHA-256. Needs apt-get and dpkg-deb; installs nothing. When the system's package lists are
# empty, fresh lists are fetched into a temporary directory (the system is left untouched).
# The cache is $HEATSIM_CACHE_DIR, else $XDG_CACHE_HOME/heatsim, else ~/.cache/heatsim.
set -euo pipefail
sha=bff773d28c62e80187b2dfa8c6c8cc771a4c7707ddcdcf2e515913d322d1f548
cache=${HEATSIM_CACHE_DIR:-${XDG_CACHE_HOME:-$HOME/.cache}/heatsim}
dest="$cache/bunny.obj"
if [ -f "$dest" ] && echo "$sha  $dest" | sha256sum -c --status; then
  echo "bunny: cached at $dest"; exit 0
fi
tmp=$(mktemp -d); trap 'rm -rf "$tmp"' EXIT
if ! (cd "$tmp" && apt-get download -q glmark2-data >/dev/null 2>&1); then
  echo "bunny: the system's package lists do not know glmark2-data; using private lists" >&2
  mkdir -p "$tmp/lists/partial" "$tmp/cache/archives/partial"
  priv=(-o "Dir::State::Lists=$tmp/lists" -o "Dir::Cache=$tmp/cache" -o Debug::NoLocking=1)
  apt-get -qq "${priv[@]}" update
  (cd "$tmp" && apt-get -q "${priv[@]}" download glmark2-data >/dev/null)
fi
dpkg-deb -x "$tmp"/glmark2-data_*.deb "$tmp/root"
src="$tmp/root/usr/share/glmark2/models/bunny.obj"
echo "$sha  $src" | sha256sum -c --status || { echo "bunny: checksum mismatch for $src" >&2; exit 1; }
mkdir -p "$cache"; cp "$src" "$dest.tmp.$$"; mv "$dest.tmp.$$" "$dest"
echo "bunny: fetched to $dest"
