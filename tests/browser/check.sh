#!/usr/bin/env bash
# The comparison page (index.html of `fogplanes table`) in a real browser: checks that the
# page's script (src/page/viewer.js) parses (`node --check`), renders a small table of the
# benchmark scene with the release binary, installs playwright-core (npm ci, here), and runs
# check_page.mjs in headless Chromium: the images decode, the screenshot is not blank, a number
# key changes the shown image (also one pressed while the images still decode), zoom, pan,
# exposure, the error view, the table rows and the plot work, nothing is fetched and nothing is
# logged as an error.
#
#   tests/browser/check.sh [--resolution WxH] [--planes N] [--out DIR]
#   tests/browser/check.sh --page path/to/index.html      (check a page already written)
#
# Needs node (>= 20) and npm, and Debian's chromium (/usr/bin/chromium, or set $CHROMIUM);
# without them it says SKIPPED and exits 0. Not part of `cargo test` or CI. Screenshots are
# written to DIR/screenshots (with --page: beside the page). Exit code 1 if any check fails.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/../.." && pwd)"
resolution=160x90
planes=5120
out=""
page=""
while [ $# -gt 0 ]; do
    case "$1" in
        --resolution) resolution="$2"; shift 2 ;;
        --planes) planes="$2"; shift 2 ;;
        --out) out="$2"; shift 2 ;;
        --page) page="$2"; shift 2 ;;
        -h|--help) sed -n '2,15p' "$0"; exit 0 ;;
        *) echo "check.sh: unknown argument $1" >&2; exit 2 ;;
    esac
done

skip() {
    echo >&2
    echo "==================================================================================" >&2
    echo "SKIPPED: $1" >&2
    echo "         the comparison page was NOT checked in a browser" >&2
    echo "==================================================================================" >&2
    exit 0
}
chromium="${CHROMIUM:-/usr/bin/chromium}"
command -v node >/dev/null || skip "node is not installed (apt-get install nodejs npm)"
node --check "$root/src/page/viewer.js"   # syntax only; runs even where the browser is missing
echo "node --check src/page/viewer.js: ok" >&2
command -v npm >/dev/null || skip "npm is not installed (apt-get install npm)"
[ -x "$chromium" ] || skip "no chromium at $chromium (apt-get install chromium, or set CHROMIUM)"
node_major="$(node -p 'process.versions.node.split(".")[0]')"
[ "$node_major" -ge 20 ] || skip "node $(node --version) is older than 20 (playwright-core needs 20)"

if [ -z "$page" ]; then
    if [ -z "$out" ]; then
        out="$(mktemp -d "${TMPDIR:-/tmp}/fogplanes-browser-check.XXXXXX")"
    fi
    mkdir -p "$out"
    (cd "$root" && cargo build --release --quiet)
    bin="$root/target/release/fogplanes"
    scene="$root/media_scenes/six_lights.toml"
    echo "rendering a $resolution table of the benchmark scene ($planes planes) in $out" >&2
    "$bin" reference "$scene" --resolution "$resolution" --pixel-center --spp 256 --quiet -o "$out/ref.exr"
    "$bin" table "$scene" --resolution "$resolution" --reference "$out/ref.exr" --planes "$planes" \
        --sweep "$((planes / 4)),$((planes / 2))" --sweep-seeds 1 --quiet --out "$out/table" >/dev/null
    page="$out/table/index.html"
    shots="$out/screenshots"
else
    [ -f "$page" ] || { echo "check.sh: no page at $page" >&2; exit 2; }
    shots="$(dirname "$page")"
fi
echo "page: $page ($(wc -c <"$page") bytes)" >&2

(cd "$here" && npm ci --no-audit --no-fund --loglevel=error >&2)
CHROMIUM="$chromium" node "$here/check_page.mjs" "$page" --shots "$shots"
