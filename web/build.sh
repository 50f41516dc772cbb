#!/bin/sh
# Build the workbench bundle into gateway/workbench/static/ (committed: no npm or CDN at run time).
# Reproducible: exact versions from package-lock.json (npm ci) and a pinned esbuild.
set -eu
cd "$(dirname "$0")"
out=../gateway/workbench/static
npm ci --no-audit --no-fund
rm -rf "$out"
mkdir -p "$out"
npx --no-install esbuild src/main.js --bundle --format=esm --target=es2020 --minify \
  --legal-comments=eof --charset=utf8 --outfile="$out/app.js"
cp index.html "$out/index.html"
ls -l "$out"
