#!/usr/bin/env bash
# The share of the planes swept along the lobes (docs/mathematics.md section 2.5, the `lobes`
# setting) against the error of one render at equal planes, for one scene: for each share given,
# the MSE and relMSE of one render from the spread of PAIRS disjoint pairs of seeds (for unbiased
# renders a and b, E|a - b|^2 = 2 MSE, as scripts/phase_mse.sh), and the SMAPE between the two
# renders of a pair, averaged (twice the noise of one render's: a relative measure that counts
# dim pixels as much as bright ones, as the table's SMAPE does).
#
#     scripts/lobe_shares.sh [BINARY] SCENE [PLANES] [RESOLUTION] [PAIRS] -- SHARE...
#     scripts/lobe_shares.sh target/release/fogplanes media_scenes/forward_fog.toml 40960 160x90 6 -- 0.5 0.85
set -euo pipefail
# The positional arguments up to `--`, each optional after the scene.
given=(); while [ $# -gt 0 ] && [ "$1" != "--" ]; do given+=("$1"); shift; done
[ "${1:-}" = "--" ] && shift
bin=${given[0]:-target/release/fogplanes}; scene=${given[1]:?usage: scripts/lobe_shares.sh BINARY SCENE [PLANES] [RESOLUTION] [PAIRS] -- SHARE...}
planes=${given[2]:-40960}; resolution=${given[3]:-160x90}; pairs=${given[4]:-6}
shares=("$@"); [ ${#shares[@]} -gt 0 ] || shares=(0 0.5 0.85)
tmp=$(mktemp -d); trap 'rm -rf "$tmp"' EXIT
for share in "${shares[@]}"; do
    sum=0; rel=0; smape=0
    for ((p = 0; p < pairs; p++)); do
        for s in 1 2; do
            "$bin" render "$scene" -e smis-exact --planes "$planes" --resolution "$resolution" \
                --seed $((2 * p + 100 + s)) --lobes "$share" --quiet -o "$tmp/$s.exr" >"$tmp/log" 2>&1 ||
                { cat "$tmp/log" >&2; exit 1; }
        done
        out=$("$bin" compare "$tmp/1.exr" "$tmp/2.exr")
        sum=$(awk -v a="$sum" -v b="$(awk '/^MSE/{print $2}' <<<"$out")" 'BEGIN{print a + b}')
        rel=$(awk -v a="$rel" -v b="$(awk '/^relMSE/{print $2}' <<<"$out")" 'BEGIN{print a + b}')
        smape=$(awk -v a="$smape" -v b="$(awk '/^SMAPE/{print $2}' <<<"$out")" 'BEGIN{print a + b}')
    done
    awk -v sh="$share" -v n="$planes" -v s="$sum" -v r="$rel" -v m="$smape" -v p="$pairs" \
        'BEGIN{printf "lobes %4s  smis-exact at %d planes: MSE %.3e, relMSE %.3e, SMAPE of a pair %.4f (%d pairs of seeds)\n", sh, n, s / (2 * p), r / (2 * p), m / p, p}'
done
